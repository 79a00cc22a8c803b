"""The three tasks: gymnasium's env checker, observation layouts, pixels that actually render."""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from plls_bench.envs import make_env
from tests.conftest import compose_preset


def env_cfg(task: str, runs_dir: Path):
    return compose_preset(None, runs_dir, f"env={task}").env


@pytest.mark.parametrize("task", ["mountaincar", "carracing", "cheetah"])
def test_env_passes_gymnasium_check_env(task: str, runs_dir: Path) -> None:
    env = make_env(env_cfg(task, runs_dir))
    try:
        check_env(env.unwrapped if task == "mountaincar" else env, skip_render_check=True)
    finally:
        env.close()


def test_carracing_observations_are_chw_uint8_images(runs_dir: Path) -> None:
    env = make_env(env_cfg("carracing", runs_dir))
    obs, _ = env.reset(seed=0)
    for _ in range(60):  # past the zoom-in animation
        obs, *_ = env.step(np.array([0.0, 0.5, 0.0], dtype=np.float32))
    env.close()
    assert env.observation_space == gym.spaces.Box(0, 255, (3, 96, 96), np.uint8)  # SB3 divides it by 255
    assert obs.shape == (3, 96, 96) and obs.dtype == np.uint8
    assert obs.std() > 2.5  # a real image, not blank


def test_cheetah_renders_stacked_pixels_and_repeats_actions(runs_dir: Path) -> None:
    cfg = env_cfg("cheetah", runs_dir)
    env = make_env(cfg)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (9, 84, 84) and obs.dtype == np.uint8
    assert np.array_equal(obs[:3], obs[6:]), "first observation stacks the same frame"
    total_steps = 0
    for _ in range(5):
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        total_steps += 1
        assert 0.0 <= reward <= cfg.action_repeat  # r(v) in [0, 1] per physics step
    assert not np.array_equal(obs[:3], obs[6:]), "frames change as the cheetah moves"
    assert obs.std() > 5, "pixels must show the scene"
    assert env.unwrapped._env.physics.data.time == pytest.approx(5 * cfg.action_repeat * 0.01)
    env.close()


def test_cheetah_reward_and_frames_are_dm_controls_stepped_by_hand(runs_dir: Path) -> None:
    """The pixel pipeline behind pixel SAC and DBC (docs/decisions.md#d27): an agent step's reward is
    the sum of dm_control's rewards over the repeated physics steps, its newest frame is dm_control's
    render after them, and the stack holds the last ``frame_stack`` frames, oldest first."""
    cfg = env_cfg("cheetah", runs_dir)
    env = make_env(cfg)
    from dm_control import suite  # after make_env, which picks the GL backend before mujoco loads

    obs, _ = env.reset(seed=3)
    by_hand = suite.load("cheetah", "run", task_kwargs={"random": 3, "time_limit": float("inf")})
    by_hand.reset()

    def render() -> np.ndarray:
        return by_hand.physics.render(cfg.image_size, cfg.image_size, camera_id=cfg.camera_id).transpose(2, 0, 1)

    frames = [render()] * cfg.frame_stack
    assert np.array_equal(obs, np.concatenate(frames)), "reset: the first render, stacked"
    rng = np.random.default_rng(0)
    for _ in range(cfg.frame_stack + 1):
        action = rng.uniform(-1, 1, size=env.action_space.shape).astype(np.float32)
        obs, reward, *_ = env.step(action)
        expected = sum(by_hand.step(action.astype(np.float64)).reward for _ in range(cfg.action_repeat))
        frames = [*frames[1:], render()]
        assert reward == pytest.approx(expected, rel=1e-12), "the reward of every repeated physics step, summed"
        assert np.array_equal(obs, np.concatenate(frames)), "the newest render last, the oldest dropped"
    env.close()


def _floor_texture_rgb(env: gym.Env) -> np.ndarray:
    """The mean colour ``(3,)`` of the model's floor checker texture."""
    model = env.unwrapped._env.physics.model
    grid = [model.texture(i).name for i in range(model.ntex)].index("grid")
    size = model.tex_width[grid] * model.tex_height[grid] * model.tex_nchannel[grid]
    texels = model.tex_data[model.tex_adr[grid]:model.tex_adr[grid] + size]
    return texels.reshape(-1, model.tex_nchannel[grid])[:, :3].mean(0)


def test_the_dbc_reference_look_restyles_the_floor_and_nothing_else(runs_dir: Path) -> None:
    """``env.visuals=dbc_reference``: the grey floor checker of the DBC reference's suite copy where
    dm_control's is blue, the same physics and rewards for the same seed and actions."""
    stock = make_env(env_cfg("cheetah", runs_dir))
    styled = make_env(compose_preset(None, runs_dir, "env=cheetah", "env.visuals=dbc_reference").env)
    try:
        (obs_stock, _), (obs_styled, _) = stock.reset(seed=3), styled.reset(seed=3)
        rng = np.random.default_rng(0)
        for _ in range(5):
            action = rng.uniform(-1, 1, 6).astype(np.float32)
            (obs_stock, r_stock, *_), (obs_styled, r_styled, *_) = stock.step(action), styled.step(action)
            assert r_stock == r_styled
        qpos = [env.unwrapped._env.physics.data.qpos.copy() for env in (stock, styled)]
        assert np.array_equal(*qpos) and not np.array_equal(obs_stock, obs_styled)
        blue, grey = _floor_texture_rgb(stock), _floor_texture_rgb(styled)
    finally:
        stock.close()
        styled.close()
    assert blue[2] > blue[0] + 30, blue
    assert np.ptp(grey) < 1 and grey[0] < blue[2], grey


def test_cheetah_episode_is_250_agent_steps_at_repeat_4(runs_dir: Path) -> None:
    env = make_env(env_cfg("cheetah", runs_dir), for_data=True)  # state-only: fast
    env.reset(seed=0)
    steps, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        assert not terminated
        steps += 1
    assert steps == 250


@pytest.mark.parametrize(("limit", "agent_steps"), [(150, 38), (1500, 375)])
def test_cheetah_episode_ends_at_env_max_episode_steps(limit: int, agent_steps: int, runs_dir: Path) -> None:
    """``env.max_episode_steps`` (frames) replaces dm_control's 1000-step time limit, either way:
    it was ignored once, so a shorter episode silently ran to 1000 frames."""
    cfg = compose_preset(None, runs_dir, "env=cheetah", f"env.max_episode_steps={limit}").env
    env = make_env(cfg, for_data=True)
    env.reset(seed=0)
    steps, truncated = 0, False
    while not truncated:
        steps += 1
        truncated = env.step(env.action_space.sample())[3]
    assert steps == agent_steps and env.unwrapped._env.physics.data.time == pytest.approx(limit * 0.01)
    env.close()


def test_same_seed_same_first_observation(runs_dir: Path) -> None:
    for task in ("mountaincar", "cheetah"):
        env = make_env(env_cfg(task, runs_dir))
        first, _ = env.reset(seed=7)
        again, _ = env.reset(seed=7)
        other, _ = env.reset(seed=8)
        env.close()
        assert np.array_equal(first, again) and not np.array_equal(first, other), task
