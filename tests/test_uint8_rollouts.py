"""uint8 rollouts: raw CarRacing frames stay uint8 from the env to PPO's rollout buffer, and the
networks see exactly the float frames they saw when the envs returned float32 in [0, 1]."""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from plls_bench.repr.latent_wrappers import LatentObservation
from plls_bench.repr.train import new_model as new_vae
from plls_bench.train.networks import ChannelsLastPolicy, policy_kwargs
from plls_bench.train.ppo_model import build_vec_env, new_model
from tests.conftest import compose_preset

LEGACY = gym.spaces.Box(0.0, 1.0, (3, 96, 96), np.float32)  # what the envs returned before


def frames(n: int = 8) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (n, 3, 96, 96), dtype=np.uint8)


def test_policy_on_uint8_frames_equals_the_float_path_bitwise(runs_dir: Path, one_torch_thread: None) -> None:
    cfg = compose_preset("carracing_ppo", runs_dir)
    venv = build_vec_env(cfg, 1, seed=0)
    space = venv.observation_space
    venv.close()
    assert space == gym.spaces.Box(0, 255, (3, 96, 96), np.uint8)
    action = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    kwargs = policy_kwargs(cfg.algo.ppo, cfg.precision)
    torch.manual_seed(0)
    now = ChannelsLastPolicy(space, action, lambda _: 1e-4, **kwargs)
    before = ChannelsLastPolicy(LEGACY, action, lambda _: 1e-4, **kwargs)
    before.load_state_dict(now.state_dict())
    obs = frames()
    with torch.no_grad():
        features = now.extract_features(torch.as_tensor(obs), now.features_extractor)
        old = torch.as_tensor(obs.astype(np.float32) / 255.0)  # the envs' old conversion
        features_old = before.extract_features(old, before.features_extractor)
        dist, dist_old = now.get_distribution(torch.as_tensor(obs)), before.get_distribution(old)
        values, values_old = now.predict_values(torch.as_tensor(obs)), before.predict_values(old)
    assert torch.equal(features, features_old)
    assert torch.equal(dist.distribution.mean, dist_old.distribution.mean)
    assert torch.equal(values, values_old)


def test_v_s_sees_the_frames_it_was_trained_on(runs_dir: Path, one_torch_thread: None) -> None:
    from plls_bench.repr.fit import Split

    cfg = compose_preset("carracing_ppo_vs", runs_dir)
    torch.manual_seed(0)
    vae = new_vae(cfg, "state").eval()
    obs = frames()
    train_batch = Split(obs, np.arange(len(obs))).batch(np.arange(len(obs)), torch.device("cpu"))
    assert torch.equal(train_batch, torch.as_tensor(obs.astype(np.float32) / 255.0))
    venv = build_vec_env(compose_preset("carracing_ppo", runs_dir), 1, seed=0)
    try:
        z = LatentObservation(venv, vae).encode(obs)
    finally:
        venv.close()
    with torch.no_grad():
        expected = vae.encode(train_batch)[0].numpy()
    assert z.dtype == np.float32 and np.array_equal(z, expected)


def test_rollout_buffer_holds_uint8(runs_dir: Path, one_torch_thread: None) -> None:
    cfg = compose_preset("carracing_ppo", runs_dir, "algo.ppo.n_envs=2", "algo.ppo.n_steps=4",
                         "algo.ppo.batch_size=8", "algo.ppo.vec_env=dummy")
    venv = build_vec_env(cfg, 2, seed=0)
    try:
        model = new_model(cfg, venv)
        model.learn(8)
    finally:
        venv.close()
    stored = model.rollout_buffer.observations
    assert stored.dtype == np.uint8 and stored.shape == (4 * 2, 3, 96, 96) and stored.std() > 2.5  # flattened by get()
    paper = compose_preset("carracing_ppo", runs_dir, "budget=paper").algo.ppo
    assert (paper.n_envs, paper.n_steps) == (16, 1000)  # Table 2
    frame = model.observation_space
    size = paper.n_envs * paper.n_steps * int(np.prod(frame.shape)) * frame.dtype.itemsize
    assert size == 442_368_000  # 0.44 GB; the float32 buffer before was 4x that, 1.77 GB
