#!/usr/bin/env python3
"""Where the test suite's time goes (issue 60): every test binary of `cargo test --release`,
run one after another as cargo runs them, with its wall and CPU seconds, and every test's own
time (libtest's --report-time, through RUSTC_BOOTSTRAP=1 at run time only: the binaries are
the ordinary stable build).

    python3 tools/suite_profile.py                  # builds, runs, prints Markdown
    python3 tools/suite_profile.py --out docs/suite_profile.md --top 25

Run it on an idle machine: another job on the cores inflates every number. A kernel test
binary re-runs itself at other subgroup sizes in child processes; their time is in the
parent's wall and CPU columns (and in the test that spawns them).
"""

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_binaries():
    """(name, path) of every test binary `cargo test --release` runs, in cargo's order."""
    out = subprocess.run(
        ["cargo", "test", "--release", "--no-run", "--message-format=json"],
        check=True,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    ).stdout
    bins = []
    for line in out.splitlines():
        try:
            m = json.loads(line)
        except json.JSONDecodeError:
            continue
        if m.get("reason") != "compiler-artifact" or not m.get("executable"):
            continue
        if not m.get("profile", {}).get("test"):
            continue
        t = m["target"]
        kind = t["kind"][0]
        name = t["name"] if kind == "test" else f"{t['name']} ({kind} unit tests)"
        bins.append((name, m["executable"]))
    return bins


def run_binary(path):
    """Runs one binary; returns wall s, CPU s (user + sys of it and its children), per-test
    times, and whether every test passed."""
    env = dict(os.environ, RUSTC_BOOTSTRAP="1")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    p = subprocess.run(
        [path, "-Z", "unstable-options", "--report-time", "--format", "json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
        cwd=ROOT,  # where cargo runs them: the package root
    )
    wall = time.monotonic() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    tests = []
    for line in p.stdout.splitlines():
        try:
            e = json.loads(line)
        except json.JSONDecodeError:
            continue
        if e.get("type") == "test" and "exec_time" in e:
            tests.append((e["name"], e["exec_time"], e["event"]))
    return wall, cpu, tests, p.returncode == 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", help="write the Markdown here as well as to stdout")
    ap.add_argument("--top", type=int, default=20, help="slowest tests listed")
    ap.add_argument("--only", action="append", help="profile only this binary (repeatable)")
    a = ap.parse_args()
    rows, all_tests, ok = [], [], True
    for name, path in test_binaries():
        if a.only and name.split(" ")[0] not in a.only:
            continue
        print(f"running {name} ...", file=sys.stderr, flush=True)
        wall, cpu, tests, passed = run_binary(path)
        ok &= passed
        rows.append((name, wall, cpu, len(tests)))
        all_tests += [(name, t, s, ev) for t, s, ev in tests]
    total_wall = sum(r[1] for r in rows)
    total_cpu = sum(r[2] for r in rows)
    md = [
        f"Suite profile: {len(rows)} test binaries, {len(all_tests)} tests, "
        f"{total_wall:.0f} s wall, {total_cpu:.0f} s CPU "
        f"({os.cpu_count()} cores, {platform.node()}, {time.strftime('%Y-%m-%d')}); "
        f"{'every test passed' if ok else 'SOME TESTS FAILED'}.",
        "",
        "| binary | tests | wall s | CPU s | share of wall |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, wall, cpu, n in sorted(rows, key=lambda r: -r[1]):
        md.append(f"| {name} | {n} | {wall:.1f} | {cpu:.1f} | {100 * wall / total_wall:.1f} % |")
    md += ["", f"The {a.top} slowest tests (their own wall time; tests of a binary run in "
           "parallel threads, so these overlap):", "",
           "| binary | test | s |", "|---|---|---:|"]
    for name, t, s, ev in sorted(all_tests, key=lambda x: -x[2])[: a.top]:
        md.append(f"| {name} | {t}{'' if ev == 'ok' else ' (' + ev + ')'} | {s:.1f} |")
    text = "\n".join(md) + "\n"
    print(text)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
