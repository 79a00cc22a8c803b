"""Does the suite's DBC update compute what the reference's does? Both, side by side, from one state.

    python -m plls_bench.validation.dbc_reference_parity --reference PATH --out results/analysis
    python -m plls_bench.validation.dbc_reference_parity --agent baseline --reference PATH --out results/analysis

PATH is a git checkout of facebookresearch/deep_bisim4control. ``--agent bisim`` (default) compares
``cheetah_dbc`` with its ``BisimAgent``; ``--agent baseline`` compares ``cheetah_sac_pixel`` (the
pixel-SAC pipeline check) with its ``BaselineAgent`` at ``--decoder_type identity``. Its modules are
imported from there, nothing of it is copied here; ``gym``, which only its env wrappers use, is
stood in for by an empty module unless installed.

Both agents start from the suite's initial weights, copied parameter by parameter into the
reference's networks (the same layers in the same order), and take the same updates on the same
minibatches of one replay: the runner's warm-up of uniform-random agent steps on cheetah-run
pixels, with the preset's ``algo.dbc`` settings. The two codes draw an update's
randomness in different calls, so it is fixed in both: Gaussian noise (the actor's sample, the
transition model's) is zero and the bisimulation loss pairs the batch by one fixed permutation.

Reported per update: the latent's std over a held-out batch (``latent_batch_std``, the statistic
that reads 0.0 when DBC's latent collapses) from each, and the largest absolute parameter
difference per network. In float64, differences at rounding level mean one computation; a
different coefficient, rate, order or loss shows at the first update as a difference of the
order of a learning rate (1e-3), far above :data:`SAME_UPDATE`. float32 shows how far rounding
alone takes them apart: Adam moves a weight by about its learning rate whatever its gradient's
size, so a near-zero gradient whose sign rounding flips separates the copies by up to 2 x lr.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import sys
import types
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import torch
import torch.nn as nn

from baselines.dbc import Batch, DBCAgent
from baselines.dbc.bisim import latent_batch_std
from baselines.dbc.encoder import ConvTrunk
from plls_bench.config import Config
from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json
from plls_bench.core.seeding import seed_everything
from plls_bench.repr.pixel_trunk import conv_stack
from plls_bench.repr.store import Representations
from plls_bench.train.dbc import make_envs
from plls_bench.validation.parity_report import ReferenceAgent, markdown, reference_commit
from plls_bench.validation.precision import machine
from plls_bench.validation.precision_runs import Sizes, dbc_config, fill_replay, random_steps

SEED = 20261126
SAME_UPDATE = 1e-9  # float64: a few updates' rounding is ~1e-13; any algorithmic difference is ~1e-4 or more
DTYPES = {"float64": torch.float64, "float32": torch.float32}


AGENTS = {
    "bisim": ReferenceAgent("bisim_agent", "BisimAgent", "cheetah_dbc", "DBC", "dbc_reference_parity", True),
    "baseline": ReferenceAgent("baseline_agent", "BaselineAgent", "cheetah_sac_pixel", "Pixel SAC",
                               "sac_pixel_reference_parity", False),
}


@dataclass(frozen=True)
class Side:
    """One implementation as the comparison drives it: an update, its networks by suite name, its
    temperature's log and its critic encoder on observations ``(B, C, H, W)``."""

    update: Callable[[Batch, int], None]
    networks: dict[str, nn.Module]
    log_alpha: torch.Tensor
    encode: Callable[[torch.Tensor], torch.Tensor]


def suite_side(agent: DBCAgent) -> Side:
    return Side(agent.update, agent.modules(), agent.log_alpha, agent.critic.encoder)


def import_reference(path: Path, agent: ReferenceAgent = AGENTS["bisim"]) -> type:
    """The reference's class of ``agent``, imported from the checkout at ``path``."""
    if not (path / "agent" / f"{agent.module}.py").is_file():
        raise SystemExit(f"--reference: {path} has no agent/{agent.module}.py "
                         "(a facebookresearch/deep_bisim4control checkout)")
    if "gym" not in sys.modules:  # only utils.FrameStack(gym.Wrapper) needs it, at class definition
        stand_in = types.ModuleType("gym")
        stand_in.Wrapper, stand_in.spaces = object, types.SimpleNamespace(Box=None)  # type: ignore[attr-defined]
        sys.modules["gym"] = stand_in
    sys.path[:0] = [str(path), str(path / "agent")]
    return getattr(importlib.import_module(agent.module), agent.name)


def reference_side(agent_class: type, cfg: Config, obs_shape: tuple[int, ...], action_dim: int,
                   networks: Iterable[str]) -> Side:
    """The reference's agent with ``algo.dbc``'s settings, driven through its own ``update``: its
    ``BisimAgent`` with ``encoder=bisim``, else its ``BaselineAgent`` at decoder_type identity (whose
    transition model is built but never trained, so only ``networks``, the suite's, are compared)."""
    dbc = cfg.algo.dbc
    assert dbc is not None
    transition = dbc.transition_model if dbc.transition_model == "probabilistic" else ""
    bisim = dbc.encoder == "bisim"  # the preset's config decides both sides (main checks the agent agrees)
    own = {"bisim_coef": dbc.bisim_coef} if bisim else {"transition_model_type": transition}
    agent = agent_class(
        obs_shape, (action_dim,), "cpu", *([transition] if bisim else []),
        hidden_dim=dbc.hidden_dim, discount=dbc.discount, init_temperature=dbc.init_temperature,
        alpha_lr=dbc.alpha_lr, alpha_beta=dbc.alpha_beta, actor_lr=dbc.actor_lr, actor_beta=dbc.actor_beta,
        actor_log_std_min=dbc.actor_log_std_min, actor_log_std_max=dbc.actor_log_std_max,
        actor_update_freq=dbc.actor_update_freq, critic_lr=dbc.critic_lr, critic_beta=dbc.critic_beta,
        critic_tau=dbc.critic_tau, critic_target_update_freq=dbc.critic_target_update_freq, encoder_type="pixel",
        encoder_feature_dim=dbc.encoder_feature_dim, encoder_lr=dbc.encoder_lr, encoder_tau=dbc.encoder_tau,
        decoder_type="identity", decoder_lr=dbc.decoder_lr, decoder_weight_lambda=dbc.decoder_weight_lambda,
        num_layers=dbc.num_layers, num_filters=dbc.num_filters, **own)
    silent = mock.MagicMock()  # its logger: every call accepted, nothing written

    def update(batch: Batch, step: int) -> None:
        sample = (batch.obs.to(batch.reward.dtype), batch.action, None, batch.reward,
                  batch.next_obs.to(batch.reward.dtype), batch.not_done)
        agent.update(types.SimpleNamespace(sample=lambda: sample), silent, step)

    dtype = torch.get_default_dtype()
    modules = {name: getattr(agent, name) for name in networks}
    return Side(update, modules, agent.log_alpha, lambda obs: agent.critic.encoder(obs.to(dtype)))


def copy_weights(source: Side, target: Side) -> None:
    """Load ``source``'s parameters and temperature into ``target``'s, network by network in
    order; ValueError naming the network whose layers differ."""
    with torch.no_grad():
        for name, module in source.networks.items():
            ours, theirs = list(module.parameters()), list(target.networks[name].parameters())
            if [p.shape for p in ours] != [p.shape for p in theirs]:
                raise ValueError(f"{name}: the two implementations' layers differ in number or shape")
            for a, b in zip(ours, theirs):
                b.copy_(a)
        target.log_alpha.fill_(float(source.log_alpha))


def max_differences(a: Side, b: Side) -> dict[str, float]:
    """The largest absolute parameter difference per network."""
    with torch.no_grad():
        return {name: max(float((p - q).abs().max()) for p, q in zip(m.parameters(), b.networks[name].parameters()))
                for name, m in a.networks.items()}


@contextlib.contextmanager
def fixed_randomness(perm: np.ndarray) -> Iterator[None]:
    """Zero Gaussian noise and one bisimulation pairing in both codes."""
    with mock.patch("torch.randn_like", lambda t, **_: torch.zeros_like(t)), \
            mock.patch("torch.randperm", lambda n, **_: torch.as_tensor(perm)), \
            mock.patch("numpy.random.permutation", lambda n: perm.copy()):
        yield


@contextlib.contextmanager
def default_dtype(dtype: torch.dtype) -> Iterator[None]:
    """Build and run in ``dtype``; the suite's conv trunk casts frames to float32, so in float64
    it casts to float64 instead (the comparison's only change to the suite's code path)."""
    before = torch.get_default_dtype()
    torch.set_default_dtype(dtype)
    try:
        if dtype == torch.float32:
            yield
        else:
            forward = lambda self, obs: self.convs(obs.to(dtype) / 255.0).flatten(1)  # noqa: E731
            with mock.patch.object(ConvTrunk, "forward", forward):
                yield
    finally:
        torch.set_default_dtype(before)


def side_by_side(suite: Side, reference: Side, batches: list[Batch], heldout: torch.Tensor,
                 perm: np.ndarray) -> list[dict[str, Any]]:
    """Both take the same updates (agent steps 1, 2, ...); a row per update and one before."""
    def row(update: int) -> dict[str, Any]:
        with torch.no_grad():
            spreads = [latent_batch_std(side.encode(heldout)) for side in (suite, reference)]
        return {"update": update, "suite_spread": spreads[0], "reference_spread": spreads[1],
                "max_difference": max_differences(suite, reference)}

    rows = [row(0)]
    with fixed_randomness(perm):
        for step, batch in enumerate(batches, start=1):
            suite.update(batch, step)
            reference.update(batch, step)
            rows.append(row(step))
    return rows


def cast(batch: Batch, dtype: torch.dtype) -> Batch:
    """Float fields in ``dtype``; frames stay uint8 (each encoder scales them)."""
    return replace(batch, action=batch.action.to(dtype), reward=batch.reward.to(dtype),
                   not_done=batch.not_done.to(dtype))


# ------------------------------------------------------------------------------------- driver
def replay_batches(cfg: Config, steps: int, updates: int) -> tuple[list[Batch], torch.Tensor]:
    """``updates`` minibatches and one held-out batch of observations from a replay of ``steps``
    uniform-random agent steps, stored as the ``dbc`` runner stores them."""
    dbc = cfg.algo.dbc
    assert dbc is not None
    seed_everything(SEED)
    train_env, eval_env = make_envs(cfg, SEED, Representations())
    try:
        replay = fill_replay(cfg, random_steps(train_env, steps, np.random.default_rng(SEED)))
    finally:
        train_env.close()
        eval_env.close()
    rng = np.random.default_rng(SEED + 1)
    batches = [replay.sample(dbc.batch_size, rng, torch.device("cpu")) for _ in range(updates + 1)]
    return batches[:-1], batches[-1].obs


def compare(agent_class: type, cfg: Config, batches: list[Batch], heldout: torch.Tensor,
            dtype: torch.dtype) -> list[dict[str, Any]]:
    """The rows of :func:`side_by_side` for a suite agent and a reference agent built in ``dtype``."""
    assert cfg.algo.dbc is not None
    obs_shape, action_dim = tuple(heldout.shape[1:]), int(batches[0].action.shape[1])
    with default_dtype(dtype):
        torch.manual_seed(SEED)
        suite = suite_side(DBCAgent(obs_shape, action_dim, cfg.algo.dbc, "cpu", conv_stack(cfg.precision)))
        reference = reference_side(agent_class, cfg, obs_shape, action_dim, suite.networks)
        copy_weights(suite, reference)
        perm = np.random.default_rng(SEED + 2).permutation(cfg.algo.dbc.batch_size)
        return side_by_side(suite, reference, [cast(b, dtype) for b in batches], heldout, perm)


def same_update(rows: list[dict[str, Any]]) -> bool:
    """Every parameter of every network agrees to :data:`SAME_UPDATE` after every update."""
    return largest_difference(rows) <= SAME_UPDATE


def largest_difference(rows: list[dict[str, Any]]) -> float:
    return max(v for row in rows for v in row["max_difference"].values())


def verdict(rows: list[dict[str, Any]]) -> str:
    """The float64 rows' reading, with the largest difference seen."""
    seen = f"largest parameter difference {largest_difference(rows):.2g} over {len(rows) - 1} updates"
    if same_update(rows):
        return f"the same update: in float64 every parameter agrees within {SAME_UPDATE:g} ({seen})"
    return f"different updates: in float64 some parameter differs by more than {SAME_UPDATE:g} ({seen})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--reference", type=Path, required=True, help="a facebookresearch/deep_bisim4control checkout")
    parser.add_argument("--steps", type=int, default=300, help="uniform-random agent steps in the replay")
    parser.add_argument("--updates", type=int, default=6, help="updates each implementation takes")
    parser.add_argument("--agent", choices=sorted(AGENTS), default="bisim",
                        help="bisim: cheetah_dbc against BisimAgent; baseline: cheetah_sac_pixel against BaselineAgent")
    parser.add_argument("--out", type=Path, default=None, help="folder for the report (.md, .json), named by --agent")
    args = parser.parse_args(argv)
    agent = AGENTS[args.agent]
    agent_class = import_reference(args.reference.resolve(), agent)  # a bad path fails before any env is built
    torch.set_num_threads(1)
    cfg = dbc_config("fp32", Sizes(), agent.preset)
    if (cfg.algo.dbc.encoder == "bisim") != agent.bisim:
        trains = "trains" if agent.bisim else "has no"
        raise SystemExit(f"--agent {args.agent}: preset {agent.preset} has algo.dbc.encoder="
                         f"{cfg.algo.dbc.encoder}, but {agent.name} {trains} bisimulation")
    batches, heldout = replay_batches(cfg, args.steps, args.updates)
    dtypes = {name: compare(agent_class, cfg, batches, heldout, dtype) for name, dtype in DTYPES.items()}
    same = same_update(dtypes["float64"])
    report = {"command": "python -m plls_bench.validation.dbc_reference_parity " + " ".join(argv or sys.argv[1:]),
              "reference_commit": reference_commit(args.reference), "machine": machine(), "steps": args.steps,
              "updates": args.updates, "batch": cfg.algo.dbc.batch_size, "agent": args.agent, "same_update": same,
              "verdict": verdict(dtypes["float64"]),
              "dtypes": dtypes}
    print(markdown(report, agent))
    if args.out is not None:
        atomic_write_json(args.out / f"{agent.report}.json", report)
        atomic_write_bytes(args.out / f"{agent.report}.md", (markdown(report, agent) + "\n").encode())
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
