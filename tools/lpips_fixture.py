#!/usr/bin/env python3
"""Make tests/lpips/ — the fixture that proves dispflow-vk's LPIPS equal to the reference.

Builds the reference network `lpips.LPIPS(net='alex', pretrained=True, pnet_rand=True)`: the
package's own linear weights (bundled in the pip package, nothing downloaded) on a torchvision
AlexNet with RANDOM weights (seeded). Every weight is rounded to float16 in the network itself,
so the f16 file we store (half the size of f32) holds exactly the weights the reference used.

Writes
  tests/lpips/alex_random_f16.safetensors  the weights, through tools/lpips_weights.py's converter
  tests/lpips/pairs.safetensors            image pairs (u8 [H, W, 3]) and the reference's values:
      pairN.img0, pairN.img1, pairN.lpips (f64 [1], the f32 network), pairN.stages (f64 [5],
      per relu stage), pairN.lpips_f64 (f64 [1], the same network run in float64)

  python3 -m venv /tmp/lpvenv && /tmp/lpvenv/bin/pip install torch torchvision lpips
  /tmp/lpvenv/bin/python tools/lpips_fixture.py
"""
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import lpips  # noqa: E402
import torchvision  # noqa: E402
import lpips_weights  # noqa: E402

SEED = 18
# (width, height, how the second image differs). Sizes: odd, the 31×31 minimum, one ≥ 100 px
# so every stage has spatial extent (relu3..5 are 5×5 at 112×100).
PAIRS = [(64, 48, "noise"), (112, 100, "blur"), (31, 31, "other"), (75, 53, "shift"),
         (40, 36, "same")]
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "lpips")


def smooth_image(rng, w, h):
    """Colourful, structured content: a few random sinusoids plus blocky noise, in [0, 1]."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.zeros((h, w, 3))
    for c in range(3):
        for _ in range(4):
            fx, fy, ph = rng.uniform(0.02, 0.3), rng.uniform(0.02, 0.3), rng.uniform(0, 6.3)
            img[..., c] += np.sin(fx * x + fy * y + ph)
        blocks = rng.uniform(-1, 1, (h // 4 + 1, w // 4 + 1))
        img[..., c] += np.kron(blocks, np.ones((4, 4)))[:h, :w]
    img = (img - img.min()) / (img.max() - img.min())
    return img


def to_u8(img):
    return np.clip(np.round(img * 255), 0, 255).astype(np.uint8)


def second(rng, a, kind):
    if kind == "noise":
        return a + rng.normal(0, 0.08, a.shape)
    if kind == "blur":
        p = np.pad(a, ((1, 1), (1, 1), (0, 0)), mode="edge")
        return sum(p[dy:dy + a.shape[0], dx:dx + a.shape[1]] for dy in range(3) for dx in range(3)) / 9
    if kind == "other":
        return smooth_image(rng, a.shape[1], a.shape[0])
    if kind == "shift":
        return np.roll(a, (2, 3), axis=(0, 1)) * 0.9 + 0.05
    if kind == "same":
        return a
    raise ValueError(kind)


def main():
    torch.manual_seed(SEED)
    rng = np.random.default_rng(SEED)
    net = lpips.LPIPS(net="alex", pretrained=True, pnet_rand=True, verbose=False).eval()
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(p.half().float())
    sd = net.state_dict()
    os.makedirs(OUT, exist_ok=True)
    bb = lpips_weights.backbone_tensors(sd)
    ln = lpips_weights.lin_tensors(sd)
    meta = {"source": f"tools/lpips_fixture.py seed {SEED}: random AlexNet, lpips alex.pth lins",
            "torch": torch.__version__, "torchvision": torchvision.__version__,
            "lpips": "0.1.4"}
    lpips_weights.convert(bb, ln, os.path.join(OUT, "alex_random_f16.safetensors"), "f16", meta)

    net64 = lpips.LPIPS(net="alex", pretrained=True, pnet_rand=True, verbose=False).eval().double()
    net64.load_state_dict({k: v.double() for k, v in sd.items()})
    tensors = []
    for i, (w, h, kind) in enumerate(PAIRS):
        a = smooth_image(rng, w, h)
        b = second(rng, a, kind)
        ua, ub = to_u8(a), to_u8(b)
        x0, x1 = (torch.from_numpy(u).permute(2, 0, 1)[None].float() / 255 for u in (ua, ub))
        with torch.no_grad():
            val, per = net(x0, x1, retPerLayer=True, normalize=True)
            val64 = net64(x0.double(), x1.double(), normalize=True)
        stages = np.array([float(s.flatten()[0]) for s in per], dtype=np.float64)
        print(f"pair{i} {w}x{h} {kind}: lpips {float(val):.6f} (f64 {float(val64):.6f}) "
              f"stages {np.array2string(stages, precision=5)}")
        tensors += [(f"pair{i}.img0", ua, "U8"), (f"pair{i}.img1", ub, "U8"),
                    (f"pair{i}.lpips", np.array([float(val)]), "F64"),
                    (f"pair{i}.stages", stages, "F64"),
                    (f"pair{i}.lpips_f64", np.array([float(val64)]), "F64")]
    lpips_weights.write_safetensors(os.path.join(OUT, "pairs.safetensors"), tensors,
                                    dict(meta, pairs=str(PAIRS)))
    for f in sorted(os.listdir(OUT)):
        print(f, os.path.getsize(os.path.join(OUT, f)), "bytes")


if __name__ == "__main__":
    main()
