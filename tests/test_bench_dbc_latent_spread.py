"""The helpers of ``bench/dbc_latent_spread.py`` on a tiny pixel agent (nothing here is timed)."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from baselines.dbc import DBCAgent
from baselines.dbc.bisim import latent_batch_std
from bench.dbc_latent_spread import encoder_at_init, spread_curve, update
from tests.test_dbc_agent import changed, params, pixel_batch, small_cfg

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def tiny_agent(runs_dir: Path) -> DBCAgent:
    torch.manual_seed(0)
    return DBCAgent((9, 84, 84), 6, small_cfg(runs_dir))


def test_the_spread_curve_has_one_value_per_count_starting_from_the_initial_weights(runs_dir: Path) -> None:
    agent, heldout = tiny_agent(runs_dir), pixel_batch(8).obs
    with torch.no_grad():
        initial = latent_batch_std(agent.critic.encoder(heldout))
    curve = spread_curve(agent, "all", lambda: pixel_batch(8), heldout, [0, 1, 3])
    assert len(curve) == 3 and curve[0] == pytest.approx(initial)
    assert curve[1] != pytest.approx(curve[0]), "an update moved the encoder"


def test_each_loss_group_trains_only_what_its_losses_reach(runs_dir: Path) -> None:
    agent = tiny_agent(runs_dir)
    actor_head, decoder = params(agent.actor.encoder.fc), params(agent.reward_decoder)
    update(agent, "critic", pixel_batch(8), 1)
    assert not changed(actor_head, agent.actor.encoder.fc) and not changed(decoder, agent.reward_decoder)
    update(agent, "representation", pixel_batch(8), 2)
    assert changed(decoder, agent.reward_decoder) and not changed(actor_head, agent.actor.encoder.fc)
    with pytest.raises(ValueError, match="loss group must be one of"):
        update(agent, "actor", pixel_batch(8), 3)


def test_encoder_statistics_see_relu_features_and_the_linear_output(runs_dir: Path) -> None:
    stats = encoder_at_init(tiny_agent(runs_dir), pixel_batch(8).obs)
    assert set(stats) == {"feature_mean", "feature_batch_std", "linear_abs_mean", "linear_batch_std"}
    assert stats["feature_mean"] >= 0.0 and stats["feature_batch_std"] > 0.0, "ReLU features, not all equal"
