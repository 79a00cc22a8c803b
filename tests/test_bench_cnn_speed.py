"""The pure helpers of ``bench/cnn_speed.py``: FLOPs from layer shapes and the CPU-flag reader
(nothing here is timed)."""
from __future__ import annotations

from torch import nn

from bench.cnn_speed import cpu_flags, forward_macs, training_flops


def test_forward_macs_of_one_conv_matches_a_hand_count() -> None:
    # 3 -> 32 channels, kernel 4, stride 2 on 96x96: a 47x47 output, each of its 32 * 47 * 47
    # values a sum of 3 * 4 * 4 products.
    conv = nn.Conv2d(3, 32, 4, stride=2)
    assert forward_macs(conv, (3, 96, 96)) == 32 * 47 * 47 * 3 * 4 * 4


def test_forward_macs_adds_convs_and_linears_but_not_activations() -> None:
    net = nn.Sequential(nn.Conv2d(2, 4, 3, stride=1, groups=2), nn.ReLU(), nn.Flatten(), nn.Linear(4 * 3 * 3, 5))
    grouped = 4 * 3 * 3 * (2 // 2) * 3 * 3  # each output sees in_channels / groups = 1 channel
    assert forward_macs(net, (2, 5, 5)) == grouped + 36 * 5
    assert training_flops(10) == 60  # forward 2 x MACs, backward twice the forward


def test_cpu_flags_reads_the_flags_line_only() -> None:
    text = "model name\t: avx512_bf16 in a name\nflags\t\t: fpu avx2 avx512f amx_tile\nflags\t: avx512_bf16\n"
    assert cpu_flags(text, ("avx512f", "avx512_bf16", "amx_tile")) == {
        "avx512f": True, "avx512_bf16": False, "amx_tile": True}
    assert cpu_flags("", ("avx2",)) == {"avx2": False}
