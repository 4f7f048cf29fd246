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
  python3 scripts/torch_parity.py random --aam DIR --export DIR --out FILE [--seed S]
      AAM's module at the export's sizes with PyTorch's own random initialisation, saved as safetensors under AAM's
      names: the PyTorch → any4d direction (`any4d model import --from FILE --config … --names animateanymesh`).
  python3 scripts/torch_parity.py probe --aam DIR --export DIR --probe FILE [--tol T]
      Runs the loaded AAM module on the inputs of FILE (written by `any4d model probe`) and compares its outputs
      with any4d's in FILE: max |difference| / max |any4d output| per output, failing (exit 1) above T (1e-5).
      With --weights W the module loads W (AAM names, e.g. from `random`) instead of the export's weights.

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


def build_mmdit(torch, transformer, frames, channels, width, blocks, heads, text_dim, mask_channels=True):
    """AAM's DyMeshMMDiT with any4d's channel layout (docs/method.md §4.1): (T + 1) slots of C latent channels, plus
    one mask channel per slot for the input-mask and impute-until conditionings."""
    model = transformer.DyMeshMMDiT(
        device="cpu",
        dtype=torch.float32,
        input_channels=(frames + 1) * (channels + int(mask_channels)),
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


def module_for_export(torch, transformer, dymeshvae, meta):
    """The AAM module matching the sizes of an export's resolved config."""
    network = meta.get("any4d.network")
    if meta.get("any4d.names") != "animateanymesh":
        fail(2, "the export was not written with --names animateanymesh")
    cfg = json.loads(meta["any4d.config"])
    m = cfg["model"]
    if network == "mmdit":
        mask = m.get("conditioning", "input_mask") in ("input_mask", "impute_until")
        return network, build_mmdit(torch, transformer, m["frames"], m["channels"], m["width"], m["blocks"],
                                    m["heads"], m["text_dim"], mask)
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


def cmd_random(args):
    """AAM's module at an export's sizes with its own random initialisation (torch.manual_seed) plus N(0, 0.02) noise,
    saved as safetensors: the PyTorch → any4d direction (`any4d model import --names animateanymesh` reads it)."""
    torch, _, transformer, dymeshvae, _ = setup(args.aam)
    from safetensors.torch import save_file  # noqa: PLC0415

    meta, _ = read_export(args.export)
    torch.manual_seed(args.seed)
    network, module = module_for_export(torch, transformer, dymeshvae, meta)
    # AAM zero-initialises some output layers (the MMDiT's output projection): N(0, 0.02) on every parameter makes
    # each one matter to the output that is compared.
    with torch.no_grad():
        for p in module.parameters():
            p.add_(torch.randn_like(p) * 0.02)
    state = {k: v.contiguous() for k, v in module.state_dict().items()}
    save_file(state, args.out, metadata={"format": "pt"})
    print(json.dumps({"network": network, "tensors": len(state), "seed": args.seed}))


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

    if args.weights:
        meta, _ = read_export(args.export)
        network, module = module_for_export(torch, transformer, dymeshvae, meta)
        module.load_state_dict(load_file(args.weights), strict=True)
        module.eval()
    else:
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
        elif network == "dymesh_vae":
            # AAM's own encode and decode, with the posterior's mean instead of a sample and the probe's first P
            # vertices as tokens (its FPS stub returns them; index 0 is kept rather than replaced by a random one).
            dymeshvae.DiagonalGaussianDistribution.sample = lambda self: self.mean
            dymeshvae.replace_negative_indices = lambda idx, valid_len: idx
            module.num_traj = VAE_PROBE_TOKENS
            frames = probe["frames"]
            b, _, n, _ = frames.shape
            valid = torch.ones(b, n, dtype=torch.bool)
            _, x, _, e0 = module.encode(frames, valid_mask=valid, adj_matrix=chain_adjacency(torch, b, n))
            out = module.decode(x, frames[:, 0], e0)
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
    rd = sub.add_parser("random")
    rd.add_argument("--aam", required=True)
    rd.add_argument("--export", required=True)
    rd.add_argument("--out", required=True)
    rd.add_argument("--seed", type=int, default=0)
    pr = sub.add_parser("probe")
    pr.add_argument("--aam", required=True)
    pr.add_argument("--export", required=True)
    pr.add_argument("--probe", required=True)
    pr.add_argument("--tol", type=float, default=1e-5)
    pr.add_argument("--weights", help="load these AAM-named weights instead of the export's (sizes from the export)")
    args = p.parse_args(argv)
    {"keys": cmd_keys, "load": cmd_load, "random": cmd_random, "probe": cmd_probe}[args.cmd](args)


if __name__ == "__main__":
    main(sys.argv[1:])
