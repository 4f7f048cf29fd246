#!/usr/bin/env python3
"""any4d ↔ PyTorch: AnimateAnyMesh's own modules loading any4d's exported weights (docs/method.md §12).

Usage:
  python3 scripts/torch_parity.py keys --aam DIR [--out FILE]
      The state_dict keys and shapes of AAM's three networks at any4d's paper sizes (the MMDiT without its CLIP
      tower, the frame-wise VAE's DyMeshVAE modules, the sequence-wise DyMeshVAE), as JSON: what
      model/tests/fixtures/aam_state_dict_keys.json holds and `cargo test` checks any4d's export names against.
  python3 scripts/torch_parity.py load --aam DIR --export DIR
      Builds the AAM module of an `any4d model export --names animateanymesh` folder at the export's sizes (from the
      config in its header) and loads `model.safetensors` with load_state_dict(strict=True); prints the result as
      JSON ({"network", "tensors", "params", "strict": true}).
  python3 scripts/torch_parity.py probe --aam DIR --export DIR --probe FILE [--tol T]
      Runs the loaded AAM module on the inputs of FILE (written by `any4d model probe`) and compares its outputs
      with any4d's in FILE: max |difference| / max |any4d output| per output, failing (exit 1) above T (1e-5).

DIR is the user's own checkout of AnimateAnyMesh (github.com/JarrentWu1031/AnimateAnyMesh); nothing of it is part of
this repository. `transformers` and `pytorch3d` are replaced by the stubs of scripts/bench_torch_reference.py, so
torch, einops, numpy and safetensors are the only packages needed. Exit status 2: bad arguments or DIR is not an
AnimateAnyMesh checkout; 3: a package is missing; 1: a check failed.
"""

import argparse
import json
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def fail(code, msg):
    print(f"torch_parity: {msg}", file=sys.stderr)
    sys.exit(code)


def setup(aam_dir):
    try:
        import torch  # noqa: PLC0415
    except ImportError as e:
        fail(3, f"torch is not installed ({e})")
    if not os.path.isfile(os.path.join(aam_dir, "networks", "dymeshvae.py")):
        fail(2, f"{aam_dir} is not an AnimateAnyMesh checkout (no networks/dymeshvae.py)")
    sys.path.insert(0, HERE)
    import bench_torch_reference as ref  # noqa: PLC0415

    ref.install_stubs(torch)
    transformer, dymeshvae, util = ref.import_aam(aam_dir)
    return torch, ref, transformer, dymeshvae, util


# any4d's time MLP reads a sinusoid of 512 values at every width; AAM's reads one of `width` values. At the paper
# width (512) the two are the same module; at another width AAM's first time layer is rebuilt to read 512.
TIME_SINUSOID = 512

# The frame-wise VAE probe's FPS tokens: the first 64 vertices (model/src/probe.rs, VAE_PROBE).
VAE_PROBE_TOKENS = 64


def build_mmdit(torch, transformer, frames, channels, width, blocks, heads, text_dim):
    """AAM's DyMeshMMDiT with any4d's input-mask channel layout (docs/method.md §4.1)."""
    model = transformer.DyMeshMMDiT(
        device="cpu",
        dtype=torch.float32,
        input_channels=(frames + 1) * (channels + 1),
        output_channels=frames * channels,
        width=width,
        layers=blocks,
        heads=heads,
    )
    if text_dim != 768:
        model.clip_token_mlp = torch.nn.Linear(text_dim, width)
    if width != TIME_SINUSOID:
        model.time_embed.c_fc = torch.nn.Linear(TIME_SINUSOID, 4 * width)
    return model


def build_vae(dymeshvae, dim, latent, heads, dim_head, blocks, frames, tokens, framewise):
    """AAM's DyMeshVAE: at frame-wise sizes (T = 1, one frame's offset in, 3 values out) or sequence-wise;
    `blocks` is (encoder, decoder) depth."""
    return dymeshvae.DyMeshVAE(
        enc_depth=blocks[0],
        dec_depth=blocks[1],
        dim=dim,
        output_dim=3 if framewise else 3 * frames,
        latent_dim=latent,
        heads=heads,
        dim_head=dim_head,
        T=1 if framewise else frames,
        num_traj=tokens,
    )


def paper_modules(torch, transformer, dymeshvae):
    """The three networks at any4d's paper sizes (configs/rf/paper.toml, configs/vae/paper.toml and
    configs/vae/dymesh_paper.toml), as scripts/bench_torch_reference.py builds them."""
    size = sys.modules["bench_torch_reference"].SIZES["paper"]
    rf, fw, sw = size["rf"], size["vae_framewise"], size["vae_sequencewise"]
    return {
        "mmdit": build_mmdit(torch, transformer, rf["frames"], rf["channels"], rf["width"], rf["blocks"],
                             rf["heads"], rf["text_dim"]),
        "frame_vae": build_vae(dymeshvae, fw["dim"], fw["latent"], fw["heads"], fw["dim_head"], (fw["blocks"], fw["blocks"]),
                               rf["frames"], size["tokens"], True),
        "dymesh_vae": build_vae(dymeshvae, sw["dim"], sw["latent"], sw["heads"], sw["dim_head"], (sw["blocks"], sw["blocks"]),
                                rf["frames"], size["tokens"], False),
    }


def cmd_keys(args):
    torch, _, transformer, dymeshvae, _ = setup(args.aam)
    out = {}
    for name, module in paper_modules(torch, transformer, dymeshvae).items():
        out[name] = [[k, list(v.shape)] for k, v in sorted(module.state_dict().items())]
    text = json.dumps(out, indent=1) + "\n"
    if args.out:
        with open(args.out, "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text)


def read_export(export_dir):
    """(metadata, tensors as a dict of torch tensors) of an export folder's model.safetensors."""
    from safetensors import safe_open  # noqa: PLC0415

    path = os.path.join(export_dir, "model.safetensors")
    with safe_open(path, framework="pt") as f:
        meta = f.metadata() or {}
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    return meta, tensors


def toml_loads(text):
    try:
        import tomllib  # noqa: PLC0415
    except ImportError:
        fail(3, "Python 3.11 or newer is needed (tomllib)")
    return tomllib.loads(text)


def module_for_export(torch, transformer, dymeshvae, meta):
    """The AAM module matching the sizes of an export's resolved config."""
    network = meta.get("any4d.network")
    if meta.get("any4d.names") != "animateanymesh":
        fail(2, "the export was not written with --names animateanymesh")
    cfg = toml_loads(meta["any4d.config"])
    m = cfg["model"]
    if network == "mmdit":
        return network, build_mmdit(torch, transformer, m["frames"], m["channels"], m["width"], m["blocks"],
                                    m["heads"], m["text_dim"])
    body = m["body"]
    framewise = network == "frame_vae"
    frames = 1 if framewise else m["frames"]
    return network, build_vae(dymeshvae, body["width"], body["latent_channels"], body["heads"], body["head_dim"],
                              (body["enc_blocks"], body["dec_blocks"]), frames, 512, framewise)


def load_export(torch, transformer, dymeshvae, export_dir):
    meta, tensors = read_export(export_dir)
    network, module = module_for_export(torch, transformer, dymeshvae, meta)
    module.load_state_dict(tensors, strict=True)
    return network, module.eval(), tensors


def cmd_load(args):
    torch, _, transformer, dymeshvae, _ = setup(args.aam)
    network, module, tensors = load_export(torch, transformer, dymeshvae, args.export)
    params = sum(p.numel() for p in module.parameters())
    print(json.dumps({"network": network, "tensors": len(tensors), "params": params, "strict": True}))


def chain_adjacency(torch, batch, vertices):
    """The dense (B, N, N) adjacency of the probe's chain mesh (vertex i joined to i + 1)."""
    i = torch.arange(vertices - 1)
    adj = torch.zeros(vertices, vertices, dtype=torch.bool)
    adj[i, i + 1] = True
    adj[i + 1, i] = True
    return adj.unsqueeze(0).expand(batch, vertices, vertices).contiguous()


def cmd_probe(args):
    torch, ref, transformer, dymeshvae, util = setup(args.aam)
    from safetensors.torch import load_file  # noqa: PLC0415

    network, module, _ = load_export(torch, transformer, dymeshvae, args.export)
    probe = load_file(args.probe)
    with torch.no_grad():
        if network == "mmdit":
            # What DyMeshMMDiT.forward does after CLIP, with any4d's text states and keep mask as inputs.
            t_emb = module.time_embed(util.timestep_embedding(probe["tau"], TIME_SINUSOID))
            text_emb = module.clip_token_mlp(probe["text"]) * probe["keep"][:, None, None]
            out = module._forward_cogx(probe["input"], text_emb, t_emb)
        elif network == "frame_vae":
            reference, frames = probe["reference"], probe["frames"]
            b, _, n, _ = frames.shape
            tokens = VAE_PROBE_TOKENS
            idx = torch.arange(tokens).unsqueeze(0).expand(b, tokens).contiguous()
            out = ref.framewise_reconstruct(torch, module, reference, frames, chain_adjacency(torch, b, n), idx)
        else:
            fail(2, f"no probe for a {network}")
    want = probe["output"]
    if out.shape != want.shape:
        fail(1, f"output shape {tuple(out.shape)}, any4d's {tuple(want.shape)}")
    scale = want.abs().max().item()
    diff = (out - want).abs().max().item()
    rel = diff / scale if scale > 0 else diff
    ok = rel <= args.tol
    print(json.dumps({"network": network, "max_abs_diff": diff, "max_abs_output": scale, "relative": rel,
                      "tol": args.tol, "ok": ok, "torch": torch.__version__}))
    if not ok:
        sys.exit(1)


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    k = sub.add_parser("keys")
    k.add_argument("--aam", required=True)
    k.add_argument("--out")
    ld = sub.add_parser("load")
    ld.add_argument("--aam", required=True)
    ld.add_argument("--export", required=True)
    pr = sub.add_parser("probe")
    pr.add_argument("--aam", required=True)
    pr.add_argument("--export", required=True)
    pr.add_argument("--probe", required=True)
    pr.add_argument("--tol", type=float, default=1e-5)
    args = p.parse_args(argv)
    {"keys": cmd_keys, "load": cmd_load, "probe": cmd_probe}[args.cmd](args)


if __name__ == "__main__":
    main(sys.argv[1:])
