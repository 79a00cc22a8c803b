"""The updates compared by :mod:`plls_bench.validation.precision`: one PPO update of
``carracing_ppo`` and ``N`` DBC updates of ``cheetah_dbc``, from the same initial weights and the
same fixed data, per precision and minibatch order. Each returns the trained networks' outputs on
held-out observations (numpy arrays), which the validation compares.

Both learners run their own suite code: SB3's ``PPO.train`` on a rollout buffer refilled with one
fixed rollout, and ``DBCAgent.update`` on minibatches of one fixed replay. The minibatch order is
the only thing an order seed changes: numpy's global RNG for SB3's shuffling (``RolloutBuffer.get``
draws ``np.random.permutation``), the replay sampler's generator for DBC. DBC's other randomness
(the actor's Gaussian draws) is reseeded identically before every run, so it is no source of
difference between runs.
"""
from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import configure

from baselines.dbc import DBCAgent, FrameReplay
from plls_bench.config import PRECISIONS, Config
from plls_bench.core.seeding import quiet_rng, seed_everything, sub_seed
from plls_bench.repr.pixel_trunk import conv_stack
from plls_bench.repr.store import Representations
from plls_bench.rundirs.composition import compose
from plls_bench.train.dbc import make_envs, to_env_action
from plls_bench.train.ppo_model import build_vec_env, new_model

SEED = 20261124           # initial weights, fixed rollout / replay; no dataset of the suite uses it
_HELDOUT, _ORDERS, _DBC_NOISE = 1, 2, 3  # sub-streams of SEED

Outputs = dict[str, np.ndarray]  # one network's outputs on the held-out observations


@dataclass(frozen=True)
class Sizes:
    """How much data and how many updates; None keeps the preset's value (budget=quick)."""

    orders: int = 3
    ppo_envs: int | None = None       # algo.ppo.n_envs (16)
    ppo_steps: int | None = None      # algo.ppo.n_steps (1000)
    ppo_epochs: int | None = None     # algo.ppo.n_epochs (10)
    ppo_batch: int | None = None      # algo.ppo.batch_size (1000)
    dbc_transitions: int | None = None  # algo.dbc.init_steps (1000): the reference's random phase
    dbc_updates: int | None = None      # algo.dbc.init_steps: the burst of updates that follows it
    dbc_batch: int | None = None        # algo.dbc.batch_size (128)
    heldout: int = 256                # held-out observations per learner


def order_seed(k: int) -> int:
    """The seed of minibatch order ``k``."""
    return sub_seed(SEED, _ORDERS, k)


def _overrides(prefix: str, **values: int | None) -> list[str]:
    return [f"{prefix}.{key}={value}" for key, value in values.items() if value is not None]


def ppo_config(precision: str, sizes: Sizes) -> Config:
    """``carracing_ppo`` at budget=quick in ``precision``, with the sizes that are set."""
    return compose(["+experiment=carracing_ppo", "budget=quick", "progress=false", f"precision={precision}",
                    "algo.ppo.vec_env=dummy",  # speed only; envpool (quick's backend) ignores it
                    *_overrides("algo.ppo", n_envs=sizes.ppo_envs, n_steps=sizes.ppo_steps,
                                n_epochs=sizes.ppo_epochs, batch_size=sizes.ppo_batch)])


def dbc_config(precision: str, sizes: Sizes, preset: str = "cheetah_dbc") -> Config:
    """``preset`` (a ``dbc``-runner preset) at budget=quick in ``precision``, with the minibatch size if set."""
    return compose([f"+experiment={preset}", "budget=quick", "progress=false", f"precision={precision}",
                    *_overrides("algo.dbc", batch_size=sizes.dbc_batch)])


def timed(update: Callable[[str, int], Outputs], precision: str, k: int, seconds: list[float]) -> Outputs:
    """``update(precision, k)``, its CPU seconds (all threads; less disturbed by other load than
    wall time) appended to ``seconds``."""
    start = time.process_time()
    outputs = update(precision, k)
    seconds.append(time.process_time() - start)
    return outputs


# ---------------------------------------------------------------------------------------- PPO
def collect_rollout(model: PPO) -> dict[str, np.ndarray]:
    """One rollout of the model's env into its buffer (SB3's own collection, GAE included);
    returns copies of the buffer's arrays ``(T, N, ...)``."""
    _, callback = model._setup_learn(model.n_steps * model.n_envs, callback=None)
    model.collect_rollouts(model.env, callback, model.rollout_buffer, model.n_steps)
    names = ("observations", "actions", "rewards", "returns", "episode_starts", "values", "log_probs", "advantages")
    return {name: getattr(model.rollout_buffer, name).copy() for name in names}


def refill(model: PPO, rollout: dict[str, np.ndarray]) -> None:
    """The model's buffer holds ``rollout`` again, unflattened (as after collection)."""
    buffer = model.rollout_buffer
    for name, array in rollout.items():
        setattr(buffer, name, array.copy())
    buffer.generator_ready, buffer.full, buffer.pos = False, True, buffer.buffer_size


def heldout_frames(cfg: Config, model: PPO, n: int) -> np.ndarray:
    """``(n, 3, 96, 96)`` uint8 frames of other tracks (envs seeded apart), the fixed policy driving."""
    envs = cfg.algo.ppo.n_envs
    venv = build_vec_env(cfg, envs, sub_seed(SEED, _HELDOUT))
    frames, obs = [], venv.reset()
    try:
        for _ in range(math.ceil(n / envs)):
            frames.append(obs)
            obs = venv.step(model.predict(obs, deterministic=False)[0])[0]
    finally:
        venv.close()
    return np.concatenate(frames)[:n]


@torch.no_grad()
def ppo_outputs(model: PPO, frames: np.ndarray) -> Outputs:
    """The Gaussian's mean and std ``(H, A)`` and the value ``(H,)`` on ``frames`` ``(H, C, H, W)``."""
    obs = model.policy.obs_to_tensor(frames)[0]
    dist = model.policy.get_distribution(obs).distribution
    return {"mean": dist.mean.numpy().astype(np.float64), "std": dist.stddev.numpy().astype(np.float64),
            "value": model.policy.predict_values(obs).flatten().numpy().astype(np.float64)}


def ppo_runs(sizes: Sizes, log: Callable[[str], None]) -> dict[str, Any]:
    """Outputs of the initial policy and of one PPO update per precision and order."""
    cfgs = {p: ppo_config(p, sizes) for p in PRECISIONS}
    seed_everything(SEED)
    venv = build_vec_env(cfgs["fp32"], cfgs["fp32"].algo.ppo.n_envs, SEED)
    models = {"fp32": new_model(cfgs["fp32"], venv)}
    with quiet_rng():  # its own init is replaced by the fp32 model's weights
        models["bf16"] = new_model(cfgs["bf16"], venv)
    for model in models.values():
        model.set_logger(configure(None, []))  # PPO.train records its losses; nothing is written
    start = copy.deepcopy((models["fp32"].policy.state_dict(), models["fp32"].policy.optimizer.state_dict()))
    log(f"PPO: collecting {venv.num_envs} x {models['fp32'].n_steps} steps")
    rollout = collect_rollout(models["fp32"])
    frames = heldout_frames(cfgs["fp32"], models["fp32"], sizes.heldout)
    venv.close()
    models["bf16"].policy.load_state_dict(start[0])
    out: dict[str, Any] = {"initial": ppo_outputs(models["fp32"], frames), "fp32": [], "bf16": [],
                           "initial_bf16": ppo_outputs(models["bf16"], frames)}

    def update(precision: str, k: int) -> Outputs:
        model = models[precision]
        model.policy.load_state_dict(start[0])
        model.policy.optimizer.load_state_dict(start[1])
        refill(model, rollout)
        np.random.seed(order_seed(k))  # SB3 shuffles the buffer with numpy's global RNG
        model.train()
        return ppo_outputs(model, frames)

    out["cpu_seconds"] = {p: [] for p in PRECISIONS}
    for precision in PRECISIONS:
        for k in range(sizes.orders):
            log(f"PPO: {precision} update, order {k}")
            out[precision].append(timed(update, precision, k, out["cpu_seconds"][precision]))
    out["fp32_repeat"] = update("fp32", 0)  # the same order again: is the comparison deterministic?
    ppo = cfgs["fp32"].algo.ppo
    out["sizes"] = {"envs": ppo.n_envs, "steps": ppo.n_steps, "epochs": ppo.n_epochs, "batch": ppo.batch_size,
                    "heldout": len(frames)}
    return out


# ---------------------------------------------------------------------------------------- DBC
def random_steps(env, n: int, rng: np.random.Generator) -> list[tuple]:
    """``n`` agent steps of uniform actions in [-1, 1] (the runner's random phase): tuples
    ``(obs, action, reward, terminated, stored next obs, next obs, done)``."""
    action_dim, steps, obs = int(np.prod(env.action_space.shape)), [], env.reset()
    for _ in range(n):
        action = rng.uniform(-1.0, 1.0, size=(1, action_dim)).astype(np.float32)
        next_obs, reward, done, info = env.step(to_env_action(action, env.action_space))
        terminated = bool(done[0]) and not info[0].get("TimeLimit.truncated", False)
        final = info[0]["terminal_observation"] if done[0] else next_obs[0]
        steps.append((obs[0], action[0], float(reward[0]), terminated, final, next_obs[0], bool(done[0])))
        obs = next_obs
    return steps


def fill_replay(cfg: Config, steps: list[tuple]) -> FrameReplay:
    """A replay holding ``steps`` exactly as the ``dbc`` runner stores them."""
    obs_shape, action_dim = steps[0][0].shape, len(steps[0][1])
    replay = FrameReplay(obs_shape, cfg.env.frame_stack, action_dim, capacity=len(steps) + 1,
                         episode_length=math.ceil(cfg.env.max_episode_steps / cfg.env.action_repeat))
    replay.start_episode(steps[0][0])
    for _, action, reward, terminated, final, next_obs, done in steps:
        replay.add(action, reward, terminated, final)
        if done:
            replay.start_episode(next_obs)
    return replay


@torch.no_grad()
def dbc_outputs(agent: DBCAgent, obs: torch.Tensor, actions: torch.Tensor) -> Outputs:
    """Critic ``q1, q2`` ``(H, 1)``, the actor's mean action ``tanh(mu)`` ``(H, A)`` and the
    critic encoder's latent ``(H, Z)`` on held-out ``obs`` ``(H, C, H, W)`` and ``actions`` ``(H, A)``."""
    features = agent.critic.encoder.features(obs)
    q1, q2 = agent.critic(features, actions)
    mean_action = agent.actor(features, sample=False)[0]
    latent = agent.critic.encoder.head(features)
    return {name: t.numpy().astype(np.float64) for name, t in
            {"q1": q1, "q2": q2, "action": mean_action, "latent": latent}.items()}


def dbc_runs(sizes: Sizes, log: Callable[[str], None]) -> dict[str, Any]:
    """Outputs of the initial agent and of ``dbc_updates`` DBC updates per precision and order."""
    cfgs = {p: dbc_config(p, sizes) for p in PRECISIONS}
    dbc = cfgs["fp32"].algo.dbc
    transitions, updates = sizes.dbc_transitions or dbc.init_steps, sizes.dbc_updates or dbc.init_steps
    seed_everything(SEED)
    train_env, heldout_env = make_envs(cfgs["fp32"], SEED, Representations())
    log(f"DBC: {transitions} random transitions (+ {sizes.heldout} held out)")
    try:
        replay = fill_replay(cfgs["fp32"], random_steps(train_env, transitions, np.random.default_rng(SEED)))
        held = random_steps(heldout_env, sizes.heldout, np.random.default_rng(sub_seed(SEED, _HELDOUT)))
    finally:
        train_env.close()
        heldout_env.close()
    obs = torch.as_tensor(np.stack([s[0] for s in held]))
    actions = torch.as_tensor(np.stack([s[1] for s in held]))
    shape, action_dim = tuple(obs.shape[1:]), actions.shape[1]
    agents = {"fp32": DBCAgent(shape, action_dim, dbc, "cpu", conv_stack("fp32"))}
    with quiet_rng():
        agents["bf16"] = DBCAgent(shape, action_dim, dbc, "cpu", conv_stack("bf16"))
    start = copy.deepcopy(agents["fp32"].state_dict())
    agents["bf16"].load_state_dict(start)
    out: dict[str, Any] = {"initial": dbc_outputs(agents["fp32"], obs, actions), "fp32": [], "bf16": [],
                           "initial_bf16": dbc_outputs(agents["bf16"], obs, actions)}

    def update(precision: str, k: int) -> Outputs:
        agent, rng = agents[precision], np.random.default_rng(order_seed(k))
        agent.load_state_dict(start)
        torch.manual_seed(sub_seed(SEED, _DBC_NOISE))  # the same actor noise in every run
        for u in range(updates):  # agent steps from init_steps on, as the runner's first updates
            agent.update(replay.sample(dbc.batch_size, rng, torch.device("cpu")), dbc.init_steps + u)
        return dbc_outputs(agent, obs, actions)

    out["cpu_seconds"] = {p: [] for p in PRECISIONS}
    for precision in PRECISIONS:
        for k in range(sizes.orders):
            log(f"DBC: {precision}, {updates} updates, order {k}")
            out[precision].append(timed(update, precision, k, out["cpu_seconds"][precision]))
    out["fp32_repeat"] = update("fp32", 0)
    out["sizes"] = {"transitions": transitions, "updates": updates, "batch": dbc.batch_size, "heldout": len(held)}
    return out
