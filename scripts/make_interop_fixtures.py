#!/usr/bin/env python3
"""PyTorch pickles for model/tests/interop.rs (needs torch and an AnimateAnyMesh checkout, as
scripts/torch_parity.py):

  python3 scripts/make_interop_fixtures.py --aam DIR

- model/tests/fixtures/aam_tiny_frame_vae.pth: AnimateAnyMesh's DyMeshVAE at FrameVaeConfig::tiny()'s frame-wise
  sizes (d 32, C 4, 2 + 2 blocks, 2 heads of 16, T = 1), every parameter filled with `(i mod 97) / 97 − 0.5` over
  its row-major PyTorch layout (i the element index), saved as AnimateAnyMesh's training script saves a checkpoint:
  a dictionary with `model_state_dict`, an optimiser state and the argparse options (an object that is not a
  tensor).
- model/tests/fixtures/evil.pt: a pickle whose loading would run `os.system` (it must be refused, never run).
- model/tests/fixtures/huge_view.pt: {"x": a stride-0 view of one float standing for 2^31 of them} (a few hundred
  bytes that would cost 8 GiB if read before being checked; burn's reader itself refuses views of over 10 GiB).
"""

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "model", "tests", "fixtures")


class Evil:
    def __reduce__(self):
        return (os.system, ("echo this pickle ran code",))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--aam", required=True)
    args = p.parse_args()
    sys.path.insert(0, HERE)
    import torch_parity  # noqa: PLC0415

    torch, _, _, dymeshvae, _ = torch_parity.setup(args.aam)
    vae = torch_parity.build_vae(dymeshvae, 32, 4, 2, 16, (2, 2), 1, 64, True)
    state = {}
    for name, value in vae.state_dict().items():
        n = value.numel()
        filled = ((torch.arange(n) % 97).float() / 97.0 - 0.5).reshape(value.shape)
        state[name] = filled if name not in ("point_embed.basis", "traj_embed.freq_bands") else value
    checkpoint = {
        "global_iter": 3,
        "model_state_dict": state,
        "optimizer_state_dict": {"state": {}, "param_groups": [{"lr": 1e-4}]},
        "opt": argparse.Namespace(lr=1e-4, exp_name="tiny"),
    }
    torch.save(checkpoint, os.path.join(OUT, "aam_tiny_frame_vae.pth"))
    torch.save(Evil(), os.path.join(OUT, "evil.pt"))
    torch.save({"x": torch.zeros(1).expand(2**31)}, os.path.join(OUT, "huge_view.pt"))


if __name__ == "__main__":
    main()
