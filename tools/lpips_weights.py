#!/usr/bin/env python3
"""Convert the reference LPIPS (AlexNet) weights into dispflow-vk's weight file.

Inputs (PyTorch files you already have; nothing is downloaded):
  --alexnet  a torchvision AlexNet state dict (e.g. alexnet-owt-7be5be79.pth from the torch hub
             cache, ~/.cache/torch/hub/checkpoints/), keys features.{0,3,6,8,10}.{weight,bias};
             an lpips.LPIPS state dict (keys net.sliceK.N.*) is accepted too.
  --lin      the lpips package's linear weights, weights/v0.1/alex.pth inside the installed
             package (default: found through `import lpips`), keys lin{0..4}.model.1.weight.
Output: a safetensors file with metadata format=dispflow-lpips, version=1, net=alex and the
tensors conv1..5.weight/bias and lin1..5.weight (see src/eval/lpips.rs for the table).

  python tools/lpips_weights.py --alexnet alexnet-owt-7be5be79.pth --out lpips_alex.safetensors
  dispflow-vk eval --run RUN --lpips-weights lpips_alex.safetensors

Needs torch (to unpickle .pth files) and numpy; writes the safetensors container itself.
"""
import argparse
import json
import os
import struct
import sys

import numpy as np

# torchvision AlexNet `features` index of each conv, and its expected shape.
CONVS = [(0, (64, 3, 11, 11)), (3, (192, 64, 5, 5)), (6, (384, 192, 3, 3)),
         (8, (256, 384, 3, 3)), (10, (256, 256, 3, 3))]
DTYPES = {"f32": (np.float32, "F32"), "f16": (np.float16, "F16")}


def write_safetensors(path, tensors, metadata):
    """tensors: list of (name, numpy array, safetensors dtype string)."""
    header = {"__metadata__": metadata}
    offset = 0
    blobs = []
    for name, arr, dt in tensors:
        b = np.ascontiguousarray(arr).tobytes()
        header[name] = {"dtype": dt, "shape": list(arr.shape), "data_offsets": [offset, offset + len(b)]}
        offset += len(b)
        blobs.append(b)
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * (-len(h) % 8)  # 8-byte alignment of the data, as the reference writer does
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(h)))
        f.write(h)
        for b in blobs:
            f.write(b)
    os.replace(tmp, path)


def _state_dict(obj):
    if isinstance(obj, dict) and "state_dict" in obj:
        obj = obj["state_dict"]
    if hasattr(obj, "state_dict"):
        obj = obj.state_dict()
    return {k.removeprefix("module."): v for k, v in obj.items()}


def backbone_tensors(sd):
    """conv{i}.weight/bias as float32 numpy from a torchvision or lpips state dict."""
    out = {}
    for i, (idx, shape) in enumerate(CONVS):
        for part in ("weight", "bias"):
            cands = [f"features.{idx}.{part}"] + [f"net.slice{s}.{idx}.{part}" for s in range(1, 6)]
            key = next((k for k in cands if k in sd), None)
            if key is None:
                sys.exit(f"AlexNet state dict: no {cands[0]} (conv{i + 1}.{part})")
            t = sd[key].detach().cpu().float().numpy()
            want = shape if part == "weight" else shape[:1]
            if t.shape != want:
                sys.exit(f"AlexNet state dict: {key} has shape {t.shape}, expected {want}")
            out[f"conv{i + 1}.{part}"] = t
    return out


def lin_tensors(sd):
    out = {}
    for i, (_, shape) in enumerate(CONVS):
        cands = [f"lin{i}.model.1.weight", f"lins.{i}.model.1.weight"]
        key = next((k for k in cands if k in sd), None)
        if key is None:
            sys.exit(f"lpips linear weights: no {cands[0]}")
        t = sd[key].detach().cpu().float().numpy()
        if t.shape != (1, shape[0], 1, 1):
            sys.exit(f"lpips linear weights: {key} has shape {t.shape}, expected (1, {shape[0]}, 1, 1)")
        out[f"lin{i + 1}.weight"] = t
    return out


def convert(backbone, lins, out_path, dtype="f32", extra_meta=None):
    np_dt, st_dt = DTYPES[dtype]
    tensors = []
    for i in range(1, 6):
        for part in ("weight", "bias"):
            tensors.append((f"conv{i}.{part}", backbone[f"conv{i}.{part}"].astype(np_dt), st_dt))
    for i in range(1, 6):
        tensors.append((f"lin{i}.weight", lins[f"lin{i}.weight"].astype(np_dt), st_dt))
    for name, arr, _ in tensors:
        if not np.isfinite(arr.astype(np.float32)).all():
            sys.exit(f"{name}: non-finite values after conversion to {dtype}")
    meta = {"format": "dispflow-lpips", "version": "1", "net": "alex"}
    meta.update(extra_meta or {})
    write_safetensors(out_path, tensors, meta)


def default_lin():
    import lpips  # only to locate the package's bundled alex.pth
    return os.path.join(os.path.dirname(lpips.__file__), "weights", "v0.1", "alex.pth")


def main():
    import torch
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--alexnet", required=True)
    ap.add_argument("--lin", default=None)
    ap.add_argument("--out", required=True)
    ap.add_argument("--dtype", choices=sorted(DTYPES), default="f32")
    a = ap.parse_args()
    lin = a.lin or default_lin()
    bb = backbone_tensors(_state_dict(torch.load(a.alexnet, map_location="cpu", weights_only=True)))
    ln = lin_tensors(_state_dict(torch.load(lin, map_location="cpu", weights_only=True)))
    convert(bb, ln, a.out, a.dtype, {"alexnet": os.path.basename(a.alexnet), "lin": os.path.basename(lin)})
    print(f"wrote {a.out} ({os.path.getsize(a.out)} bytes)")


if __name__ == "__main__":
    main()
