#!/usr/bin/env python3
"""PyTorch's side of the paper-size RF forward + backward, by operator (torch.profiler), at THREADS threads.

    python3 torch_profile.py AAM_DIR THREADS [math] > torch-profile-tTHREADS.txt

Builds the same network and step as scripts/bench_torch_reference.py (AnimateAnyMesh's DyMeshMMDiT, batch 1, 512
latent tokens, 77 text tokens, width 512, 12 blocks) and prints the median step time over 5 steps, then the
profiler's table of the 3 profiled steps sorted by self CPU time. With `math`, scaled_dot_product_attention is
restricted to its unfused math kernel (matmul, softmax, matmul: the same arrangement as ours under autodiff).
"""
import os
import sys
import time

aam, threads = sys.argv[1], int(sys.argv[2])
math_only = len(sys.argv) > 3 and sys.argv[3] == "math"
for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[var] = str(threads)
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
import contextlib  # noqa: E402
import warnings  # noqa: E402

import torch  # noqa: E402

import bench_torch_reference as ref  # noqa: E402

warnings.filterwarnings("ignore", category=UserWarning)
torch.set_num_threads(threads)
torch.set_num_interop_threads(1)
torch.manual_seed(0)
ref.install_stubs(torch)
transformer, _dymeshvae, util = ref.import_aam(aam)
cfg, p_tok, l_txt = ref.SIZES["paper"]["rf"], ref.SIZES["paper"]["tokens"], ref.SIZES["paper"]["text_len"]
in_ch = (cfg["frames"] + 1) * (cfg["channels"] + 1)
out_ch = cfg["frames"] * cfg["channels"]
model = transformer.DyMeshMMDiT(device="cpu", dtype=torch.float32, input_channels=in_ch, output_channels=out_ch,
                                width=cfg["width"], layers=cfg["blocks"], heads=cfg["heads"])
model.train()
width = model.backbone.width


def step():
    x = torch.randn(1, p_tok, in_ch)
    text = torch.randn(1, l_txt, cfg["text_dim"])
    target = torch.randn(1, p_tok, out_ch)
    tau = torch.rand(1)
    start = time.perf_counter()
    t_emb = model.time_embed(util.timestep_embedding(tau, width))
    loss = (model._forward_cogx(x, model.clip_token_mlp(text), t_emb) - target).square().mean()
    loss.backward()
    elapsed = time.perf_counter() - start
    model.zero_grad(set_to_none=True)
    return elapsed


ctx = contextlib.nullcontext()
if math_only:
    from torch.nn.attention import SDPBackend, sdpa_kernel  # noqa: PLC0415

    ctx = sdpa_kernel([SDPBackend.MATH])
with ctx:
    step()
    times = sorted(step() for _ in range(5))
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, attention "
          f"{'math kernel only' if math_only else 'default kernels'}: median {times[2] * 1e3:.1f} ms/step "
          f"(5 steps: {', '.join(f'{t * 1e3:.0f}' for t in times)})")
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
        for _ in range(3):
            step()
print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=25, max_name_column_width=48))
