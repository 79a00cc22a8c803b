"""The DBC reference-parity harness (``plls_bench.validation.dbc_reference_parity``) without the
reference checkout: two suite agents stand in for the two implementations, so the harness must
call one computation the same and tell a changed coefficient apart at the first update."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from baselines.dbc import Batch, DBCAgent
from plls_bench.validation import dbc_reference_parity as parity
from tests.conftest import compose_preset

OBS = (9, 36, 36)  # small frames: the conv trunk sizes its Linear layer from them


def batches(n: int, size: int = 16) -> list[Batch]:
    g = torch.Generator().manual_seed(0)
    frames = lambda: torch.randint(0, 256, (size, *OBS), generator=g, dtype=torch.uint8)  # noqa: E731
    return [Batch(obs=frames(), action=torch.rand(size, 6, generator=g) * 2 - 1,
                  reward=torch.rand(size, 1, generator=g), next_obs=frames(), not_done=torch.ones(size, 1))
            for _ in range(n)]


def sides(runs_dir: Path, *other_overrides: str, preset: str = "cheetah_dbc") -> tuple[parity.Side, parity.Side]:
    small = ("algo.dbc.hidden_dim=32",)
    cfgs = [compose_preset(preset, runs_dir, *small, *extra).algo.dbc for extra in ((), other_overrides)]
    torch.manual_seed(0)
    first, second = (parity.suite_side(DBCAgent(OBS, 6, cfg)) for cfg in cfgs)
    return first, second


@pytest.mark.parametrize("preset, other, same", [
    ("cheetah_dbc", (), True), ("cheetah_dbc", ("algo.dbc.bisim_coef=0.25",), False),
    ("cheetah_dbc", ("algo.dbc.encoder_tau=0.5",), False),
    ("cheetah_sac_pixel", (), True), ("cheetah_sac_pixel", ("algo.dbc.critic_lr=0.01",), False)])
def test_one_computation_is_the_same_update_and_a_changed_setting_is_not(
        runs_dir: Path, preset: str, other: tuple[str, ...], same: bool) -> None:
    with parity.default_dtype(torch.float64):
        first, second = sides(runs_dir, *other, preset=preset)
        parity.copy_weights(first, second)
        data = [parity.cast(b, torch.float64) for b in batches(3)]
        rows = parity.side_by_side(first, second, data[:2], data[2].obs, np.arange(16)[::-1].copy())
    assert [r["update"] for r in rows] == [0, 1, 2]
    assert all(v == 0.0 for v in rows[0]["max_difference"].values()), "copied weights start equal"
    assert parity.same_update(rows) is same
    if not same:  # a learning rate's order of magnitude, at the update where the setting acts
        assert max(max(r["max_difference"].values()) for r in rows) > 1e-6


def test_the_fixed_randomness_is_zero_noise_and_one_pairing() -> None:
    perm = np.array([2, 0, 1])
    with parity.fixed_randomness(perm):
        assert torch.equal(torch.randn_like(torch.ones(4)), torch.zeros(4))
        assert torch.randperm(3).tolist() == [2, 0, 1] and np.random.permutation(3).tolist() == [2, 0, 1]
    assert torch.randn_like(torch.ones(64)).abs().sum() > 0, "restored afterwards"


def test_layers_that_differ_are_named(runs_dir: Path) -> None:
    first, _ = sides(runs_dir)
    torch.manual_seed(0)
    wider = compose_preset("cheetah_dbc", runs_dir, "algo.dbc.hidden_dim=64").algo.dbc
    second = parity.suite_side(DBCAgent(OBS, 6, wider))
    with pytest.raises(ValueError, match="^actor: the two implementations' layers differ"):
        parity.copy_weights(first, second)


@pytest.mark.parametrize("agent, module", [([], "bisim_agent"), (["--agent", "baseline"], "baseline_agent")])
def test_a_path_without_the_reference_is_refused_before_any_work(
        tmp_path: Path, agent: list[str], module: str) -> None:
    with pytest.raises(SystemExit, match=f"--reference: .* has no agent/{module}.py"):
        parity.main(["--reference", str(tmp_path), *agent])


def test_each_agent_names_a_preset_of_its_kind(runs_dir: Path) -> None:
    """The baseline is compared on the pixel-SAC preset (encoder trained by the critic), DBC on DBC's."""
    encoders = {name: compose_preset(agent.preset, runs_dir).algo.dbc.encoder for name, agent in parity.AGENTS.items()}
    assert encoders == {"bisim": "bisim", "baseline": "critic"}


def test_the_float64_trunk_is_restored(runs_dir: Path) -> None:
    with parity.default_dtype(torch.float64):
        agent = DBCAgent(OBS, 6, compose_preset("cheetah_dbc", runs_dir, "algo.dbc.hidden_dim=32").algo.dbc)
        assert agent.critic.encoder(batches(1)[0].obs).dtype == torch.float64
    assert torch.get_default_dtype() == torch.float32
    agent = DBCAgent(OBS, 6, compose_preset("cheetah_dbc", runs_dir, "algo.dbc.hidden_dim=32").algo.dbc)
    assert agent.critic.encoder(batches(1)[0].obs).dtype == torch.float32, "the suite's own trunk again"
