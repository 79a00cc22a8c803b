"""The paper CNN's forward+backward speed per precision and layout, against this core's matmul roof.

    nice -n 10 .venv/bin/python bench/cnn_speed.py                  # 1 torch thread
    nice -n 10 .venv/bin/python bench/cnn_speed.py --threads 1 2 --no-write

Rows, all in one run, interleaved (every setting once per round, ``--rounds`` rounds; median and
range): the ``paper_cnn`` PPO features extractor (``plls_bench.train.networks.PaperCNN`` with
``carracing_ppo``'s ``algo.ppo.cnn_*`` keys) forward and backward on a random batch, in fp32 and
under ``torch.autocast('cpu', dtype=torch.bfloat16)``, each with contiguous and channels_last
tensors (applied here, to the module and the input); a 2048x2048 matmul in fp32 and bf16 (the
roof: what one core does on the best-shaped work); V_s's encoder (``plls_bench.repr.models``, eval
mode, no grad) forward on a batch of 16 frames, per precision and layout. FLOPs come from the
layer shapes (see ``forward_macs``): forward = 2 x MACs, backward ~ 2 x forward, so a training
pass counts 3 x forward. Also prints the CPU's bf16 flags (``/proc/cpuinfo``).
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import torch
from torch import nn

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.benchmarks_md import announce, machine, write_section  # noqa: E402
from plls_bench.repr.train import new_model  # noqa: E402
from plls_bench.rundirs.composition import compose  # noqa: E402
from plls_bench.train.networks import PaperCNN  # noqa: E402

SECTION = "cnn_speed"
BF16_FLAGS = ("avx512f", "avx512_bf16", "amx_bf16", "amx_tile")
SETTINGS = {  # name -> (bf16 autocast, channels_last)
    "fp32, contiguous": (False, False),
    "fp32, channels_last": (False, True),
    "bf16 autocast, contiguous": (True, False),
    "bf16 autocast + channels_last": (True, True),
}
Rates = dict[str, list[float]]


def forward_macs(module: nn.Module, input_shape: tuple[int, ...]) -> int:
    """Multiply-accumulates of one forward pass of one sample through ``module``'s Conv2d and
    Linear layers, from the shapes each layer sees (bias adds and activations not counted)."""
    total = 0

    def count(layer: nn.Module, _: tuple, out: torch.Tensor) -> None:
        nonlocal total
        if isinstance(layer, nn.Conv2d):
            per_output = layer.in_channels // layer.groups * layer.kernel_size[0] * layer.kernel_size[1]
            total += out[0].numel() * per_output
        elif isinstance(layer, nn.Linear):
            total += layer.in_features * layer.out_features

    hooks = [m.register_forward_hook(count) for m in module.modules() if isinstance(m, (nn.Conv2d, nn.Linear))]
    try:
        with torch.no_grad():
            module(torch.zeros(1, *input_shape))
    finally:
        for hook in hooks:
            hook.remove()
    return total


def training_flops(macs: int) -> int:
    """FLOPs of a forward+backward pass: forward 2 x MACs, backward about twice the forward."""
    return 3 * 2 * macs


def cpu_flags(cpuinfo: str, names: tuple[str, ...] = BF16_FLAGS) -> dict[str, bool]:
    """Which of ``names`` the first ``flags`` line of a ``/proc/cpuinfo`` text lists."""
    line = next((ln for ln in cpuinfo.splitlines() if ln.startswith("flags")), "")
    present = set(line.partition(":")[2].split())
    return {name: name in present for name in names}


def _rate(work: Callable[[], None], items: int, min_seconds: float) -> float:
    """Items/s of ``work`` repeated until ``min_seconds`` have passed (at least once)."""
    calls, start = 0, time.perf_counter()
    while calls == 0 or time.perf_counter() - start < min_seconds:
        work()
        calls += 1
    return items * calls / (time.perf_counter() - start)


def _layout(module: nn.Module, x: torch.Tensor, channels_last: bool) -> tuple[nn.Module, torch.Tensor]:
    fmt = torch.channels_last if channels_last else torch.contiguous_format
    return copy.deepcopy(module).to(memory_format=fmt), x.contiguous(memory_format=fmt)


def _train_pass(module: nn.Module, x: torch.Tensor, bf16: bool) -> Callable[[], None]:
    def work() -> None:
        module.zero_grad(set_to_none=True)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            out = module(x)
        out.float().sum().backward()
    return work


def _inference(module: nn.Module, x: torch.Tensor, bf16: bool) -> Callable[[], None]:
    def work() -> None:
        with torch.inference_mode(), torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            module(x)
    return work


def _matmul(n: int, dtype: torch.dtype) -> Callable[[], None]:
    a, b = torch.rand(n, n).to(dtype), torch.rand(n, n).to(dtype)
    return lambda: torch.mm(a, b)


def build(batch: int, frames: int) -> tuple[dict[str, Callable[[], None]], dict[str, int], int]:
    """The timed works (name -> callable), their items per call, and the CNN's forward MACs."""
    with tempfile.TemporaryDirectory() as tmp:
        ppo_cfg = compose(["+experiment=carracing_ppo", "budget=quick", f"runs_dir={tmp}"])
        vs_cfg = compose(["+experiment=carracing_vs", "budget=quick", f"runs_dir={tmp}"])
    ppo, side = ppo_cfg.algo.ppo, ppo_cfg.env.image_size
    space = gym.spaces.Box(0.0, 1.0, (3, side, side))
    cnn = PaperCNN(space, list(ppo.cnn_channels), list(ppo.cnn_kernel_sizes), ppo.cnn_stride,
                   list(ppo.cnn_hidden), ppo.activation)
    encoder = new_model(vs_cfg, "state").encoder.eval()
    works: dict[str, Callable[[], None]] = {}
    items: dict[str, int] = {}
    for name, (bf16, last) in SETTINGS.items():
        module, x = _layout(cnn, torch.rand(batch, *space.shape), last)
        works[f"cnn|{name}"], items[f"cnn|{name}"] = _train_pass(module, x, bf16), batch
        module, x = _layout(encoder, torch.rand(frames, 3, vs_cfg.env.image_size, vs_cfg.env.image_size), last)
        works[f"enc|{name}"], items[f"enc|{name}"] = _inference(module, x, bf16), frames
    return works, items, forward_macs(cnn, space.shape)


def measure(threads: list[int], rounds: int, batch: int, frames: int, matmul: int,
            min_seconds: float) -> tuple[dict[int, Rates], int]:
    """Rates per thread count: ``cnn|...`` samples/s, ``enc|...`` frames/s, ``roof|...`` GFLOP/s."""
    works, items, macs = build(batch, frames)
    flop = 2 * matmul ** 3 / 1e9
    for dtype in (torch.float32, torch.bfloat16):
        works[f"roof|{str(dtype)[6:]}"], items[f"roof|{str(dtype)[6:]}"] = _matmul(matmul, dtype), 1
    rates: dict[int, Rates] = {t: {name: [] for name in works} for t in threads}
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(threads[0])
        for work in works.values():  # warm-up: oneDNN picks and caches its kernels
            work()
        for r in range(rounds):
            for t in threads:
                torch.set_num_threads(t)
                for name, work in works.items():
                    rate = _rate(work, items[name], min_seconds)
                    rates[t][name].append(rate * flop if name.startswith("roof|") else rate)
                    print(f"round {r + 1}, {t} thread(s), {name:36s} {rates[t][name][-1]:10.1f}", flush=True)
    finally:
        torch.set_num_threads(before)
    return rates, macs


def _cell(values: list[float], fmt: str = ",.0f") -> tuple[str, str]:
    return f"{statistics.median(values):{fmt}}", f"{min(values):{fmt}} - {max(values):{fmt}}"


def tables(rates: dict[int, Rates], macs: int) -> tuple[list[str], list[str], list[str]]:
    """Markdown rows of the three tables: CNN training pass, roof, V_s encoder."""
    gflop = training_flops(macs) / 1e9
    cnn = ["| threads | setting | samples/s (median) | range | GFLOP/s | fraction of its precision's roof "
           "| vs fp32 contiguous |", "|---|---|---|---|---|---|---|"]
    roof = ["| threads | matmul | GFLOP/s (median) | range |", "|---|---|---|---|"]
    enc = ["| threads | setting | frames/s (median) | range | vs fp32 contiguous |", "|---|---|---|---|---|"]
    for t, r in rates.items():
        base_cnn, base_enc = statistics.median(r["cnn|fp32, contiguous"]), statistics.median(r["enc|fp32, contiguous"])
        for name, (bf16, _) in SETTINGS.items():
            samples = statistics.median(r[f"cnn|{name}"])
            top = statistics.median(r["roof|bfloat16" if bf16 else "roof|float32"])
            cnn.append(f"| {t} | {name} | **{_cell(r[f'cnn|{name}'])[0]}** | {_cell(r[f'cnn|{name}'])[1]} | "
                       f"{samples * gflop:.1f} | {samples * gflop / top:.0%} | {samples / base_cnn:.2f}x |")
            frames = statistics.median(r[f"enc|{name}"])
            enc.append(f"| {t} | {name} | **{_cell(r[f'enc|{name}'])[0]}** | {_cell(r[f'enc|{name}'])[1]} | "
                       f"{frames / base_enc:.2f}x |")
        for dtype in ("float32", "bfloat16"):
            median, spread = _cell(r[f"roof|{dtype}"], ",.1f")
            roof.append(f"| {t} | {dtype} | **{median}** | {spread} |")
    return cnn, roof, enc


def _bf16_note(flags: dict[str, bool]) -> list[str]:
    """Why a bf16 fraction of the roof can pass 100% on a CPU without bf16 instructions."""
    if flags.get("avx512_bf16") or flags.get("amx_bf16"):
        return []
    return ["This CPU has neither avx512_bf16 nor amx_bf16: bf16 has no native instructions here, the "
            "bf16 matmul takes a slow fallback path, so its 'roof' is no roof and a bf16 fraction above "
            "100% means only that the convolutions' bf16 path is less slow than the matmul's.", ""]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--threads", nargs="+", type=int, default=[1], help="torch intra-op thread counts")
    parser.add_argument("--batch", type=int, default=250, help="CNN training batch (Table 2's minibatch "
                        "is algo.ppo.batch_size=1000; 250 is the measuring batch of issue 20)")
    parser.add_argument("--frames", type=int, default=16, help="V_s encoder batch (16 envs per vector step)")
    parser.add_argument("--matmul", type=int, default=2048, help="side of the square roof matmul")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved measurements per setting")
    parser.add_argument("--min-seconds", type=float, default=1.0, help="repeat a work at least this long")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    args = parser.parse_args(argv)
    if min(args.threads) < 1 or min(args.batch, args.frames, args.matmul, args.rounds) < 1:
        parser.error("--threads, --batch, --frames, --matmul and --rounds must be positive")
    command = announce("cnn_speed.py", argv)
    flags = cpu_flags(Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else "")
    flag_text = ", ".join(f"{k} {'yes' if v else 'no'}" for k, v in flags.items())
    print(f"CPU flags: {flag_text}; torch CPU capability {torch.backends.cpu.get_cpu_capability()}")
    rates, macs = measure(args.threads, args.rounds, args.batch, args.frames, args.matmul, args.min_seconds)
    after, (cnn, roof, enc) = machine(), tables(rates, macs)
    print("\n".join([*cnn, "", *roof, "", *enc, f"machine (after): {after}"]))
    text = "\n".join([
        "## Paper CNN forward+backward per precision and layout, against the matmul roof (`bench/cnn_speed.py`)",
        "", f"Command: `{command}`  ", f"Machine: {after}  ",
        f"CPU flags: {flag_text}; torch CPU capability {torch.backends.cpu.get_cpu_capability()}.  ",
        f"The `paper_cnn` trunk (`PaperCNN` with `carracing_ppo`'s keys: conv 32-64-128-256, kernel 4, "
        f"stride 2 on 3x96x96, FC 4096->32->32), forward and backward (sum of outputs) at batch "
        f"{args.batch}, no optimizer step. FLOPs from the layer shapes: {macs:,} MACs per sample forward, "
        f"forward = 2 x MACs, backward counted as 2 x forward, so {training_flops(macs) / 1e9:.3f} GFLOP "
        f"per sample. bf16 is `torch.autocast('cpu', dtype=torch.bfloat16)`, channels_last is applied to "
        f"module and input. Roof: {args.matmul}x{args.matmul} `torch.mm` in that dtype. {args.rounds} rounds, "
        f"all settings and thread counts interleaved, each repeated for at least {args.min_seconds:g} s; "
        "median and range of the rounds.", "", *cnn, "", *roof, "", *_bf16_note(flags),
        f"V_s's encoder (`StateVAE.encoder`, eval, no grad), forward on {args.frames} frames:", "", *enc])
    if not args.no_write:
        write_section(SECTION, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
