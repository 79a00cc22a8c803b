"""The conv trunks' memory layout and precision (plls_bench/repr/pixel_trunk.py).

channels_last must give the contiguous layout's outputs and gradients (within 1e-5: only float
summation order changes) and share its state_dicts; bf16 must stay inside the trunks (heads,
parameters and trunk outputs float32) and be its own config hash, run dir and V_s artifact, while
fp32 keeps every existing hash.
"""
from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch import nn

from baselines.dbc.encoder import ConvTrunk
from plls_bench.core.atomic_files import read_json
from plls_bench.repr.keys import repr_key, repr_path
from plls_bench.repr.models import StateVAE
from plls_bench.repr.pixel_trunk import PixelTrunk, conv_stack, memory_format
from plls_bench.rundirs.composition import config_from_dict
from plls_bench.rundirs.run_dir import Run, config_hash, stored_identity, variant_name
from plls_bench.train.networks import ChannelsLastPolicy, PaperCNN, policy_kwargs
from tests.conftest import REPO_ROOT, compose_preset

FRAMES = gym.spaces.Box(0, 255, (3, 96, 96), np.uint8)


def ppo_policy(runs_dir: Path, *overrides: str) -> ChannelsLastPolicy:
    cfg = compose_preset("carracing_ppo", runs_dir, *overrides)
    torch.manual_seed(0)
    action = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    return ChannelsLastPolicy(FRAMES, action, lambda _: 1e-4, **policy_kwargs(cfg.algo.ppo, cfg.precision))


def state_vae(runs_dir: Path, *overrides: str) -> StateVAE:
    cfg = compose_preset("carracing_vs", runs_dir, *overrides)
    torch.manual_seed(0)
    return StateVAE(cfg.repr.state, cfg.env.image_size, precision=cfg.precision)


def dbc_trunk(runs_dir: Path, *overrides: str) -> ConvTrunk:
    cfg = compose_preset("cheetah_dbc", runs_dir, *overrides)
    torch.manual_seed(0)
    frames = (3 * cfg.env.frame_stack, cfg.env.image_size, cfg.env.image_size)
    return ConvTrunk(frames, cfg.algo.dbc.num_layers, cfg.algo.dbc.num_filters, conv_stack(cfg.precision))


Forward = Callable[[nn.Module, torch.dtype], torch.Tensor]


def trunks(runs_dir: Path) -> dict[str, tuple[nn.Module, Forward]]:
    """Each conv trunk (in channels_last, as built) and its forward on a fixed input batch, in a
    given dtype (float64 gives the reference the two float32 layouts are measured against)."""
    gen = torch.Generator().manual_seed(1)
    unit = torch.randint(0, 256, (6, 3, 96, 96), generator=gen, dtype=torch.uint8) / 255.0
    stacked = torch.randint(0, 256, (6, 9, 84, 84), generator=gen, dtype=torch.uint8) / 255.0
    z = torch.randn(6, 32, generator=gen)
    return {
        "paper_cnn": (ppo_policy(runs_dir).features_extractor, lambda m, t: m(unit.to(t))),
        "V_s.encoder": (state_vae(runs_dir), lambda m, t: torch.cat(m.encode(unit.to(t)), 1)),
        "V_s.decoder": (state_vae(runs_dir), lambda m, t: m.decode(z.to(t))),
        # ConvTrunk after its / 255
        "dbc.encoder": (dbc_trunk(runs_dir), lambda m, t: m.convs(stacked.to(t)).flatten(1)),
    }


def gradients(module: nn.Module, forward: Forward, dtype: torch.dtype,
              masks: list[torch.Tensor]) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Output and parameter gradients of one backward of a fixed random projection of the output.
    An empty ``masks`` is filled with every ReLU's ``input > 0``, in call order; a filled one is
    imposed on the ReLUs instead (see :func:`test_channels_last_matches_the_contiguous_layout`)."""
    record, calls = not masks, iter(list(masks))

    def relu(_m: nn.Module, inputs: tuple[torch.Tensor, ...], out: torch.Tensor) -> torch.Tensor | None:
        if record:
            masks.append(inputs[0].detach() > 0)
            return None
        return inputs[0] * next(calls).to(inputs[0].dtype)

    hooks = [m.register_forward_hook(relu) for m in module.modules() if isinstance(m, nn.ReLU)]
    out = forward(module, dtype)
    for hook in hooks:
        hook.remove()
    weight = torch.randn(out.shape, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    (out * weight.to(dtype)).sum().backward()
    return out.detach().double(), {n: p.grad.double() for n, p in module.named_parameters() if p.grad is not None}


def assert_within(fast: torch.Tensor, slow: torch.Tensor, what: str, tol: float = 1e-5) -> None:
    """Largest difference within ``tol`` of the tensor's own scale (its largest magnitude, at least
    1): a gradient summed over a batch's pixels differs by float rounding relative to its size."""
    fast, slow = fast.detach(), slow.detach()  # weights compared as values, not as graph nodes
    scale = max(1.0, float(slow.abs().max()))
    gap = float((fast - slow).abs().max())
    assert gap <= tol * scale, f"{what}: max difference {gap:.3g} > {tol:g} x scale {scale:.3g}"


def conv_weights(module: nn.Module) -> list[torch.Tensor]:
    return [m.weight for m in module.modules() if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d))]


@pytest.mark.parametrize("name", ["paper_cnn", "V_s.encoder", "V_s.decoder", "dbc.encoder"])
def test_channels_last_matches_the_contiguous_layout(name: str, runs_dir: Path, one_torch_thread: None) -> None:
    """Outputs and gradients within 1e-5 of the contiguous layout's (relative to each tensor's
    scale). The gradients run with every ReLU's on/off pattern taken from a float64 pass: a ReLU
    input within rounding of zero (7.8e-9 in one of these batches) flips in one float32 layout and
    not the other, moving a weight's gradient by up to 3e-3; that is rounding luck at a kink, which
    either layout can draw, not a difference between layouts."""
    fast, forward = trunks(runs_dir)[name]
    slow = copy.deepcopy(fast).to(memory_format=torch.contiguous_format)
    exact = copy.deepcopy(slow).double()
    weights = conv_weights(fast)
    assert weights and all(w.is_contiguous(memory_format=torch.channels_last) for w in weights)
    assert memory_format(fast) == torch.channels_last and memory_format(slow) == torch.contiguous_format
    masks: list[torch.Tensor] = []
    gradients(exact, forward, torch.float64, masks)
    assert masks
    seen: list[bool] = []  # the convs really compute in channels_last
    channels_last = lambda _m, _i, out: seen.append(out.is_contiguous(memory_format=torch.channels_last))  # noqa: E731
    hooks = [m.register_forward_hook(channels_last)
             for m in fast.modules() if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d))]
    out_fast, grads_fast = gradients(fast, forward, torch.float32, masks)
    for hook in hooks:
        hook.remove()
    assert seen and all(seen)
    out_slow, grads_slow = gradients(slow, forward, torch.float32, masks)
    with torch.no_grad():
        assert_within(forward(fast, torch.float32), forward(slow, torch.float32), f"{name} output")
    assert_within(out_fast, out_slow, f"{name} output, ReLUs pinned")
    assert grads_fast and set(grads_fast) == set(grads_slow)
    for n, grad in grads_slow.items():
        assert_within(grads_fast[n], grad, f"{name} gradient of {n}")


@pytest.mark.parametrize("name", ["paper_cnn", "V_s.encoder", "dbc.encoder"])
def test_state_dicts_load_across_layouts(name: str, runs_dir: Path, one_torch_thread: None) -> None:
    fast, forward = trunks(runs_dir)[name]
    slow = copy.deepcopy(fast).to(memory_format=torch.contiguous_format)
    back = copy.deepcopy(slow)
    f32 = torch.float32
    with torch.no_grad():
        for p in slow.parameters():
            p.mul_(1.01)  # other weights, saved from the contiguous layout
        for p in back.parameters():
            p.zero_()
    fast.load_state_dict(slow.state_dict())
    assert all(w.is_contiguous(memory_format=torch.channels_last) for w in conv_weights(fast))
    assert_within(forward(fast, f32), forward(slow, f32), f"{name} loaded into channels_last")
    back.load_state_dict(fast.state_dict())  # saved from channels_last, into the contiguous layout
    assert all(w.is_contiguous() for w in conv_weights(back))
    assert_within(forward(back, f32), forward(slow, f32), f"{name} loaded into the contiguous layout")


@pytest.mark.parametrize("name", ["paper_cnn", "V_s.encoder", "V_s.decoder", "dbc.encoder"])
def test_bf16_runs_the_trunk_only(name: str, runs_dir: Path, one_torch_thread: None) -> None:
    built = {"paper_cnn": lambda: ppo_policy(runs_dir, "precision=bf16"),
             "V_s.encoder": lambda: state_vae(runs_dir, "precision=bf16"),
             "V_s.decoder": lambda: state_vae(runs_dir, "precision=bf16"),
             "dbc.encoder": lambda: dbc_trunk(runs_dir, "precision=bf16")}[name]()
    built = built.features_extractor if name == "paper_cnn" else built
    fp32, forward = trunks(runs_dir)[name]
    built.load_state_dict(fp32.state_dict())
    inner: list[torch.dtype] = []
    for m in built.modules():
        if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d)):
            m.register_forward_hook(lambda _m, _i, out: inner.append(out.dtype))
    trunk_modules = [m for m in built.modules() if isinstance(m, PixelTrunk)]
    assert trunk_modules and all(t.precision == "bf16" for t in trunk_modules)
    out, reference = forward(built, torch.float32), forward(fp32, torch.float32)
    assert inner and set(inner) == {torch.bfloat16}, "the convs compute in bf16"
    assert out.dtype == torch.float32 and all(p.dtype == torch.float32 for p in built.parameters())
    assert not torch.equal(out, reference)
    torch.testing.assert_close(out, reference, atol=0.1, rtol=0.05)  # bf16 rounding, not another network


def test_ppo_heads_stay_fp32_under_bf16(runs_dir: Path, one_torch_thread: None) -> None:
    policy = ppo_policy(runs_dir, "precision=bf16")
    dtypes: list[torch.dtype] = []
    for head in (policy.action_net, policy.value_net, policy.features_extractor.fc):
        head.register_forward_hook(lambda _m, _i, out: dtypes.append(out.dtype))  # a Linear in autocast gives bf16
    values, log_prob, _ = policy.evaluate_actions(torch.zeros(2, 3, 96, 96, dtype=torch.uint8), torch.zeros(2, 3))
    assert dtypes and set(dtypes) == {torch.float32}
    assert values.dtype == log_prob.dtype == torch.float32
    assert isinstance(policy.features_extractor, PaperCNN)


def test_precision_is_hashed_recorded_and_a_run_dir_variant(runs_dir: Path) -> None:
    fp32 = compose_preset("carracing_ppo", runs_dir)
    bf16 = compose_preset("carracing_ppo", runs_dir, "precision=bf16")
    assert fp32.precision == "fp32" and bf16.precision == "bf16"
    assert config_hash(bf16) != config_hash(fp32)
    assert config_hash(compose_preset("carracing_ppo", runs_dir, "precision=fp32")) == config_hash(fp32)
    assert variant_name("auto", "precision=bf16") == "precision=bf16" != variant_name("auto", "")
    Run(runs_dir / "r").prepare(bf16, config_hash(bf16))
    provenance = read_json(runs_dir / "r" / "provenance.json")
    assert provenance["precision"] == "bf16" and provenance["starts"][0]["precision"] == "bf16"


def test_fp32_keeps_the_hashes_of_committed_records() -> None:
    """Every committed record predates ``precision``: at fp32 its config still hashes as recorded (re-hashed
    under today's rules, which leave out budget.trials: what counts a record done)."""
    paths = sorted((REPO_ROOT / "results" / "records").glob("**/config.json"))
    assert paths
    for path in paths:
        record = json.loads(path.read_text())
        cfg = config_from_dict(record["config"])
        assert cfg.precision == "fp32" and config_hash(cfg) == stored_identity(path.parent), path


def test_bf16_v_s_is_another_artifact_v_a_is_not(runs_dir: Path) -> None:
    fp32 = compose_preset("carracing_plls_ppo", runs_dir)
    bf16 = compose_preset("carracing_plls_ppo", runs_dir, "precision=bf16")
    assert "precision" not in repr_key(fp32, "state"), "fp32 artifacts keep their keys"
    assert repr_path(bf16, "state") != repr_path(fp32, "state")
    assert repr_path(bf16, "action") == repr_path(fp32, "action")  # V_a has no conv trunk
