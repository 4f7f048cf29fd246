#!/usr/bin/env python3
"""PyTorch reference for `any4d bench model`: times AnimateAnyMesh's own networks on CPU on the same shapes as ours
(docs/method.md §4.3 rectified-flow MMDiT, docs/method.md §3.2 frame-wise VAE, docs/method.md §3.5 sequence-wise DyMeshVAE).

Usage: python3 scripts/bench_torch_reference.py --aam DIR [--size paper|tiny] [--batch B] [--iters K]
                                               [--threads N] [--json]

DIR is the user's own checkout of AnimateAnyMesh (github.com/JarrentWu1031/AnimateAnyMesh); nothing of it is part of
this repository. Its `networks/transformer.py` (DyMeshMMDiT) and `networks/dymeshvae.py` (DyMeshVAE) are imported
from DIR and timed:

- rf: DyMeshMMDiT at the "40m" configuration (width 512, 12 blocks, 8 heads), input/output Linear set to our
  in/out channels (221 / 192 at paper size), forward + backward of an MSE loss on random inputs. The frozen CLIP
  text tower is not built or timed: as on our side, the (B, L, 768) text states are a random input, passed through
  AAM's clip_token_mlp, the keep mask, the time MLP and `_forward_cogx` (what `DyMeshMMDiT.forward` does after
  CLIP).
- vae_framewise: DyMeshVAE's modules built at docs/method.md §3.2 sizes (d 128, C 12, 8 + 8 blocks, 8 heads × 64, per-frame
  offset input of 3 values) and driven frame-wise as our FrameVae does: the shape stream once per clip, every
  frame's motion stream pooled with the same attention map (the value streams of all frames concatenated along
  the head channels, AAM's own v_cat trick widened to T frames), posterior mean, under torch.no_grad.
- vae_sequencewise: DyMeshVAE at its defaults (d 256, C 32, T frames in the channels) through its own
  `encode` / `decode`, under torch.no_grad.

Both VAEs use AAM's dense (B, N, N) adjacency mask of a chain mesh (vertex i joined to i + 1, as our synthetic
edge list) and the first P vertices as FPS tokens (ours too): `pytorch3d.ops.sample_farthest_points` is replaced by
a stub returning 0..P-1, and `transformers`' CLIP loaders by stubs, so neither package is needed. AAM wraps its
attention calls in `torch.backends.cuda.sdp_kernel(enable_math=False)`, which leaves no CPU kernel when the value
width differs from the query width (its Sync attention concatenates two value streams): the context manager is
replaced by a no-op, so PyTorch picks its CPU kernel (flash where the widths allow, math otherwise).

Timing: one warm-up, then the median of K runs (time.perf_counter), torch.set_num_threads(N) and one inter-op
thread. Prints one JSON object with --json ({"torch": version, "threads": N, "rf": {...}, "vae_framewise": {...},
"vae_sequencewise": {...}}, each network with "median_ms", "steps_ms", "params"), readable lines otherwise.
Exit status 2: bad arguments or DIR is not an AnimateAnyMesh checkout; 3: torch or einops is missing.
"""

import argparse
import contextlib
import json
import os
import sys
import time
import types
import warnings

SIZES = {
    # Must match model/src/bench.rs (`BenchSizes::paper` / `BenchSizes::tiny`, checked by its test).
    "paper": {
        "rf": {"width": 512, "blocks": 12, "heads": 8, "frames": 16, "channels": 12, "text_dim": 768},
        "tokens": 512,
        "text_len": 77,
        "vertices": 2048,
        "vae_framewise": {"dim": 128, "heads": 8, "dim_head": 64, "blocks": 8, "latent": 12},
        "vae_sequencewise": {"dim": 256, "heads": 8, "dim_head": 64, "blocks": 8, "latent": 32},
    },
    "tiny": {
        "rf": {"width": 32, "blocks": 2, "heads": 2, "frames": 4, "channels": 3, "text_dim": 8},
        "tokens": 64,
        "text_len": 8,
        "vertices": 256,
        "vae_framewise": {"dim": 32, "heads": 2, "dim_head": 16, "blocks": 2, "latent": 4},
        "vae_sequencewise": {"dim": 32, "heads": 2, "dim_head": 16, "blocks": 2, "latent": 4},
    },
}


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--aam", required=True, help="AnimateAnyMesh checkout (holds networks/dymeshvae.py)")
    p.add_argument("--size", choices=sorted(SIZES), default="paper")
    p.add_argument("--batch", type=int, default=1)
    p.add_argument("--iters", type=int, default=3)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--check", action="store_true", help="only check the frame-wise driver against AAM's modules")
    args = p.parse_args(argv)
    for name in ("batch", "iters", "threads"):
        if getattr(args, name) < 1:
            p.error(f"--{name} must be positive, got {getattr(args, name)}")
    for rel in ("networks/transformer.py", "networks/dymeshvae.py", "networks/util.py"):
        if not os.path.isfile(os.path.join(args.aam, rel)):
            fail(2, f"--aam {args.aam}: {rel} not found (not an AnimateAnyMesh checkout)")
    return args


def fail(code, msg):
    print(f"bench_torch_reference: {msg}", file=sys.stderr)
    sys.exit(code)


def install_stubs(torch):
    """Stand-ins for the two packages AAM imports but the timed code does not need (see the module docstring)."""

    class _Frozen:
        @staticmethod
        def from_pretrained(*_args, **_kwargs):
            return torch.nn.Identity()

    transformers = types.ModuleType("transformers")
    transformers.CLIPTextModel = _Frozen
    transformers.CLIPTokenizer = _Frozen
    sys.modules["transformers"] = transformers

    def sample_farthest_points(points, lengths=None, K=1, **_kwargs):
        b = points.shape[0]
        idx = torch.arange(K, device=points.device).unsqueeze(0).expand(b, K).contiguous()
        return None, idx

    # A CUDA-only kernel switch; on CPU it would forbid the math kernel that unequal q/v widths need.
    torch.backends.cuda.sdp_kernel = lambda **_kwargs: contextlib.nullcontext()

    pytorch3d = types.ModuleType("pytorch3d")
    ops = types.ModuleType("pytorch3d.ops")
    ops.sample_farthest_points = sample_farthest_points
    pytorch3d.ops = ops
    sys.modules["pytorch3d"] = pytorch3d
    sys.modules["pytorch3d.ops"] = ops


def import_aam(aam_dir):
    """AAM's `networks` package from the user's checkout: (transformer module, dymeshvae module, util module)."""
    sys.path.insert(0, os.path.abspath(aam_dir))
    from networks import dymeshvae, transformer, util  # noqa: PLC0415

    return transformer, dymeshvae, util


def median(values):
    s = sorted(values)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def timed(run, iters):
    """One warm-up, then `iters` timed calls: {"median_ms", "steps_ms"}."""
    run()
    steps = []
    for _ in range(iters):
        start = time.perf_counter()
        run()
        steps.append((time.perf_counter() - start) * 1e3)
    return {"median_ms": median(steps), "steps_ms": steps}


def n_params(module):
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


def bench_rf(torch, transformer, util, size, batch, iters):
    """(R4)-(R5) forward + backward of AAM's DyMeshMMDiT with our channel counts."""
    cfg, p_tok, l_txt = size["rf"], size["tokens"], size["text_len"]
    in_ch = (cfg["frames"] + 1) * (cfg["channels"] + 1)  # input_mask layout, docs/method.md §4.1
    out_ch = cfg["frames"] * cfg["channels"]
    model = transformer.DyMeshMMDiT(
        device="cpu",
        dtype=torch.float32,
        input_channels=in_ch,
        output_channels=out_ch,
        width=cfg["width"],
        layers=cfg["blocks"],
        heads=cfg["heads"],
    )
    if cfg["text_dim"] != 768:  # AAM hard-codes CLIP-L's 768; the tiny size uses our tiny text width
        model.clip_token_mlp = torch.nn.Linear(cfg["text_dim"], cfg["width"])
    model.train()
    width = model.backbone.width

    def step():
        x = torch.randn(batch, p_tok, in_ch)
        text = torch.randn(batch, l_txt, cfg["text_dim"])
        target = torch.randn(batch, p_tok, out_ch)
        tau = torch.rand(batch)
        keep = torch.ones(batch)
        start = time.perf_counter()
        t_emb = model.time_embed(util.timestep_embedding(tau, width))
        text_emb = model.clip_token_mlp(text) * keep[:, None, None]
        loss = (model._forward_cogx(x, text_emb, t_emb) - target).square().mean()
        loss.backward()
        elapsed = (time.perf_counter() - start) * 1e3
        model.zero_grad(set_to_none=True)
        return elapsed

    step()
    steps = [step() for _ in range(iters)]
    return {
        "median_ms": median(steps),
        "steps_ms": steps,
        "params": n_params(model),
        "in_channels": in_ch,
        "out_channels": out_ch,
    }


def synthetic_clip(torch, batch, vertices, frames):
    """Reference (B, N, 3), frames (B, T, N, 3), dense chain adjacency (B, N, N), valid mask (B, N): as
    model/src/summary.rs builds ours (uniform reference, N(0, 0.05) motion)."""
    reference = torch.rand(batch, vertices, 3) * 2 - 1
    frames_ = reference[:, None] + torch.randn(batch, frames, vertices, 3) * 0.05
    i = torch.arange(vertices - 1)
    adj = torch.zeros(vertices, vertices, dtype=torch.bool)
    adj[i, i + 1] = True
    adj[i + 1, i] = True
    adj = adj.unsqueeze(0).expand(batch, vertices, vertices).contiguous()
    valid = torch.ones(batch, vertices, dtype=torch.bool)
    return reference, frames_, adj, valid


def shared_map_attention(torch, pre, q_stream, k_stream, v1_stream, v2_stream):
    """AAM's SyncAttentionPreNorm + SyncAttention with the motion stream split into G groups that share the map.

    Shapes: q_stream (B, Lq, d), k_stream and v1_stream (B, Lk, d), v2_stream (B, G, Lk, d)
    -> (B, Lq, d), (B, G, Lq, d).
    """
    attn = pre.attn
    h = attn.heads
    b, lq, _ = q_stream.shape
    _, g, lk, _ = v2_stream.shape
    q = attn.to_q(pre.norm_q(q_stream))
    dh = q.shape[-1] // h
    q = q.view(b, lq, h, dh).transpose(1, 2)
    k = attn.to_k(pre.norm_k(k_stream)).view(b, lk, h, dh).transpose(1, 2)
    v1 = attn.to_v1(pre.norm_v1(v1_stream)).view(b, lk, h, dh).transpose(1, 2)
    v2 = attn.to_v2(pre.norm_v2(v2_stream)).view(b, g, lk, h, dh).permute(0, 3, 2, 1, 4).reshape(b, h, lk, g * dh)
    out = torch.nn.functional.scaled_dot_product_attention(q, k, torch.cat([v1, v2], dim=-1))
    o1 = out[..., :dh].transpose(1, 2).reshape(b, lq, h * dh)
    o2 = out[..., dh:].reshape(b, h, lq, g, dh).permute(0, 3, 2, 1, 4).reshape(b, g, lq, h * dh)
    return attn.to_out1(o1), attn.to_out2(o2)


def framewise_reconstruct(torch, vae, reference, frames, adj, idx):
    """docs/method.md §3.2 encode + decode with AAM's modules (posterior mean).

    Shapes: reference (B, N, 3), frames (B, T, N, 3), adj (B, N, N), idx (B, P) -> (B, T, N, 3).
    """
    b, t, n, _ = frames.shape
    e0 = vae.point_embed(reference)
    for layer in vae.neighbor_layers:
        e0 = e0 + layer(e0, key=e0, value=e0, mask=adj)
    d = e0.shape[-1]
    offsets = (frames - reference[:, None]).reshape(b * t, n, 3)  # r_f = x̄_f − x̄₀, frame 0 included
    motion = vae.traj_embed(offsets).view(b, t, n, d)
    p = idx.shape[1]
    s = torch.gather(e0, 1, idx[:, :, None].expand(b, p, d))
    m = torch.gather(motion, 2, idx[:, None, :, None].expand(b, t, p, d))
    for attn, ffn in vae.enc_blocks:
        ds, dm = shared_map_attention(torch, attn, s, e0, e0, motion)
        s, m = s + ds, m + dm
        s = s + ffn.ffn.ffn1(ffn.norm1(s))
        m = m + ffn.ffn.ffn2(ffn.norm2(m))
    z0 = vae.mean_fc_x0(s)
    mu = vae.mean_fc_xt(m)
    vae.logvar_fc_xt(m).clamp(-30.0, 20.0)  # computed (and dropped) as our encoder does; the mean is decoded
    s = vae.proj_x0(z0)
    m = vae.proj_xt(mu)
    for attn, ffn in vae.dec_blocks:
        ds, dm = shared_map_attention(torch, attn, s, s, s, m)
        s, m = s + ds, m + dm
        s = s + ffn.ffn.ffn1(ffn.norm1(s))
        m = m + ffn.ffn.ffn2(ffn.norm2(m))
    # Query decoding: one head of width 2d, keys from shape tokens, values from every frame's motion tokens.
    final = vae.decoder_final_ca
    qa = final.fn
    q = qa.to_q(final.norm_q(vae.fc_query(e0)))[:, None]  # (B, 1, N, 2d)
    k = qa.to_k(final.norm_k(s))[:, None]  # (B, 1, P, 2d)
    v = qa.to_v(final.norm_v(m))  # (B, T, P, 2d)
    dq = v.shape[-1]
    v = v.permute(0, 2, 1, 3).reshape(b, 1, p, t * dq)
    pooled = torch.nn.functional.scaled_dot_product_attention(q, k, v)  # (B, 1, N, T·2d)
    out = vae.to_outputs(qa.to_out(pooled.view(b, n, t, dq)))  # (B, N, T, 3)
    return reference[:, None] + out.permute(0, 2, 1, 3)


def bench_vae_framewise(torch, dymeshvae, size, batch, frames, iters):
    cfg, n, p = size["vae_framewise"], size["vertices"], size["tokens"]
    vae = dymeshvae.DyMeshVAE(
        enc_depth=cfg["blocks"],
        dec_depth=cfg["blocks"],
        dim=cfg["dim"],
        output_dim=3,
        latent_dim=cfg["latent"],
        heads=cfg["heads"],
        dim_head=cfg["dim_head"],
        T=1,  # the motion input is one frame's offset: 3 values -> 63 Fourier values
        num_traj=p,
    ).eval()
    reference, frames_, adj, _ = synthetic_clip(torch, batch, n, frames)
    idx = torch.arange(p).unsqueeze(0).expand(batch, p).contiguous()

    def run():
        with torch.no_grad():
            framewise_reconstruct(torch, vae, reference, frames_, adj, idx)

    return {**timed(run, iters), "params": n_params(vae)}


def bench_vae_sequencewise(torch, dymeshvae, size, batch, frames, iters):
    cfg, n, p = size["vae_sequencewise"], size["vertices"], size["tokens"]
    vae = dymeshvae.DyMeshVAE(
        enc_depth=cfg["blocks"],
        dec_depth=cfg["blocks"],
        dim=cfg["dim"],
        output_dim=3 * frames,
        latent_dim=cfg["latent"],
        heads=cfg["heads"],
        dim_head=cfg["dim_head"],
        T=frames,
        num_traj=p,
    ).eval()
    _, frames_, adj, valid = synthetic_clip(torch, batch, n, frames)

    def run():
        with torch.no_grad():
            _, x, _, e0 = vae.encode(frames_, valid_mask=valid, adj_matrix=adj)
            vae.decode(x, frames_[:, 0], e0)

    return {**timed(run, iters), "params": n_params(vae)}


def check_framewise_driver(torch, dymeshvae):
    """The frame-wise driver against AAM's own modules, tiny sizes, random weights: (1) with one group,
    `shared_map_attention` equals AAM's SyncAttentionPreNorm; (2) decoding T frames at once equals decoding each
    frame alone (the shared map does not mix frames). Returns (checks run, failure messages)."""
    torch.manual_seed(1)
    vae = dymeshvae.DyMeshVAE(enc_depth=2, dec_depth=2, dim=32, output_dim=3, latent_dim=4, heads=2, dim_head=16,
                              T=1, num_traj=8).eval()
    for module in vae.modules():  # AAM zero-initialises some output layers; randomise so every path counts
        if isinstance(module, torch.nn.Linear):
            torch.nn.init.normal_(module.weight, std=0.2)
    failures = []
    checks = 0
    with torch.no_grad():
        q, k, v1, v2 = (torch.randn(2, 8, 32), torch.randn(2, 20, 32), torch.randn(2, 20, 32), torch.randn(2, 20, 32))
        for name, pre in (("encoder", vae.enc_blocks[0][0]), ("decoder", vae.dec_blocks[0][0])):
            ours = shared_map_attention(torch, pre, q, k, v1, v2[:, None])
            theirs = pre(q, k, v1, v2)
            err = max((ours[0] - theirs[0]).abs().max().item(), (ours[1][:, 0] - theirs[1]).abs().max().item())
            checks += 1
            if err > 1e-5:
                failures.append(f"{name} shared_map_attention differs from AAM's SyncAttention by {err:.2e}")
        reference, frames, adj, _ = synthetic_clip(torch, 2, 20, 3)
        idx = torch.randint(0, 20, (2, 8))
        together = framewise_reconstruct(torch, vae, reference, frames, adj, idx)
        for f in range(3):
            alone = framewise_reconstruct(torch, vae, reference, frames[:, f : f + 1], adj, idx)
            err = (together[:, f] - alone[:, 0]).abs().max().item()
            checks += 1
            if err > 1e-5:
                failures.append(f"frame {f} decoded with the others differs from alone by {err:.2e}")
        checks += 1
        if (together - frames).abs().max().item() < 1e-6:
            failures.append("reconstruction equals the input: the check cannot see the network")
    return checks, failures


def main(argv):
    args = parse_args(argv)
    # Thread pools are sized when torch loads: set the OpenMP/MKL counts first.
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(args.threads)
    try:
        import torch  # noqa: PLC0415
        import einops  # noqa: F401, PLC0415  (imported by AAM's dymeshvae.py)
    except ImportError as e:
        fail(3, f"{e.name} is not installed (pip install torch einops)")
    warnings.filterwarnings("ignore", category=UserWarning)  # kernel-choice notes from scaled_dot_product_attention
    torch.set_num_threads(args.threads)
    torch.set_num_interop_threads(1)
    torch.manual_seed(0)
    install_stubs(torch)
    transformer, dymeshvae, util = import_aam(args.aam)

    if args.check:
        checks, failures = check_framewise_driver(torch, dymeshvae)
        for msg in failures:
            print(f"FAIL {msg}")
        print(f"{checks - len(failures)} passed, {len(failures)} failed")
        return 1 if failures else 0

    size = SIZES[args.size]
    frames = size["rf"]["frames"]
    result = {
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "size": args.size,
        "batch": args.batch,
        "iters": args.iters,
        "rf": bench_rf(torch, transformer, util, size, args.batch, args.iters),
        "vae_framewise": bench_vae_framewise(torch, dymeshvae, size, args.batch, frames, args.iters),
        "vae_sequencewise": bench_vae_sequencewise(torch, dymeshvae, size, args.batch, frames, args.iters),
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"torch {result['torch']}, {result['threads']} threads, {args.size}, batch {args.batch}")
        for key in ("rf", "vae_framewise", "vae_sequencewise"):
            r = result[key]
            print(f"{key}: {r['params']} params, median {r['median_ms']:.1f} ms/step, "
                  f"{r['median_ms'] / args.batch:.1f} ms/clip")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
