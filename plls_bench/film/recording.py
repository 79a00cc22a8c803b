"""Filmstrips of trained policies (Figs 11, 19, 22), recorded for ``python -m plls_bench.film RUN_DIR``.

One episode of the run's last checkpointed policy (deterministic actions, through the same
V_s / V_a wrappers as in training), reset with the trial's evaluation seed plus ``filmstrip.episode``
(the episode PPO's evaluations test each time; DBC re-seeds every evaluation, so for it the filmed
episode is none of its test episodes), with a frame every ``filmstrip.interval`` env frames and at
its last step.
Settings: ``conf/filmstrip/<env>.yaml``. Writes ``<out>/frames.npz`` (``frames`` ``(k, H, W, 3)``
uint8, ``frame_steps`` ``(k,)``) and then ``<out>/filmstrip.json`` (``interval``, ``frame_steps``,
``episode_return``, ``steps_to_goal``, ``checkpoint``, ...); ``<out>`` is ``RUN_DIR/filmstrip``,
the run's declared sub-output, written through :class:`plls_bench.rundirs.run_dir.RunOutput`: both files
atomically, then ``done.json`` with the strip's hash (:meth:`FilmstripConfig.output_hash`).
The policy loader is handed in (:func:`make_filmstrip`): which runners hold a policy to film, and
how to load it, is the runner registry's, which sits above this module; the command
``python -m plls_bench.film RUN_DIR`` looks it up there.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv

from plls_bench.config import Config, ConfigError, FilmstripConfig
from plls_bench.core.atomic_files import read_json
from plls_bench.core.seeding import derive_seeds
from plls_bench.envs import make_env
from plls_bench.repr.fit import torch_threads
from plls_bench.repr.latent_wrappers import wrap_latent
from plls_bench.repr.store import Representations, load_representations
from plls_bench.rundirs.artifacts import npz_bytes
from plls_bench.rundirs.composition import filmstrip_config
from plls_bench.rundirs.run_dir import Run, RunOutput
from plls_bench.train.trained_policy import PolicyLoader

__all__ = ["FrameRecorder", "filmstrip_config", "make_filmstrip", "record"]

Act = Callable[[np.ndarray], np.ndarray]  # batched observations (1, *O) -> actions (1, *A)


class FrameRecorder(gym.Wrapper):
    """Records the first episode of ``env``: a frame (resized to ``height``) after every
    ``interval`` env frames (``action_repeat`` per step) and at its last step, and its raw return."""

    def __init__(self, env: gym.Env, interval: int, action_repeat: int, height: int) -> None:
        super().__init__(env)
        self.interval, self.action_repeat, self.height = interval, action_repeat, height
        self.frames: list[np.ndarray] = []
        self.frame_steps: list[int] = []
        self.episode_return, self.length = 0.0, 0
        self.terminated = self.over = False

    def reset(self, **kwargs):
        out = self.env.reset(**kwargs)
        if not self.frames:  # the recorded episode's first frame; later resets are ignored
            self._grab()
        return out

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not self.over:
            self.length += 1
            self.episode_return += float(reward)
            self.terminated, self.over = bool(terminated), bool(terminated or truncated)
            if (self.length * self.action_repeat) % self.interval == 0 or self.over:
                self._grab()
        return obs, reward, terminated, truncated, info

    def finish(self) -> None:
        """End the recording (a step cap), adding the last step's frame if it is not in yet."""
        if self.frame_steps[-1] != self.length * self.action_repeat:
            self._grab()
        self.over = True

    def _grab(self) -> None:
        frame = np.asarray(self.env.render())
        if frame.shape[0] != self.height:
            width = round(frame.shape[1] * self.height / frame.shape[0])
            frame = cv2.resize(frame, (width, self.height), interpolation=cv2.INTER_AREA)
        self.frames.append(np.ascontiguousarray(frame, dtype=np.uint8))
        self.frame_steps.append(self.length * self.action_repeat)


def record(cfg: Config, act: Act, strip: FilmstripConfig, max_steps: int = 0,
           reprs: Representations | None = None) -> FrameRecorder:
    """Roll out one episode of ``act`` on ``cfg``'s task (``reprs``' V_s / V_a applied by
    ``wrap_latent``, as in training; None: loaded for ``cfg``, never trained) and return its
    recorder. ``max_steps > 0`` caps the episode (tests)."""
    if strip.interval % cfg.env.action_repeat:
        raise ConfigError(f"filmstrip.interval: {strip.interval} frames is not a multiple of "
                          f"env.action_repeat = {cfg.env.action_repeat}")
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # pygame renders off-screen (MountainCar, CarRacing)
    reprs = (reprs or load_representations(cfg)).check(cfg)  # before the env: a missing model fails fast
    recorder = FrameRecorder(make_env(cfg.env, render_mode="rgb_array"), strip.interval,
                             cfg.env.action_repeat, strip.frame_height)
    venv = wrap_latent(DummyVecEnv([lambda: recorder]), reprs)
    # One env: every forward pass is a batch of one, which a second intra-op thread only slows
    # down (10x for V_s's convolutions on a busy 2-core machine). An explicit torch_threads wins.
    with torch_threads(cfg.torch_threads or 1):
        try:
            if strip.reset_options:
                venv.set_options(dict(strip.reset_options))
            venv.seed(derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial).eval + strip.episode)
            obs = venv.reset()
            while not recorder.over and not (max_steps and recorder.length >= max_steps):
                obs, _, _, _ = venv.step(act(obs))
            recorder.finish()
        finally:
            venv.close()
    return recorder


def make_filmstrip(run_dir: Path, load: PolicyLoader, out: Path | None = None, overrides: list[str] | None = None,
                   device: str = "auto", max_steps: int = 0) -> dict:
    """Record ``run_dir``'s policy, loaded by ``load`` (its runner's), and write the filmstrip files;
    returns filmstrip.json's content."""
    record_json = read_json(run_dir / "config.json")
    if record_json is None:
        raise ConfigError(f"{run_dir}: no readable config.json, not a run directory")
    strip = filmstrip_config(record_json["config"]["env"]["name"], overrides or [])
    policy = load(run_dir, device)
    rec = record(policy.cfg, policy.act, strip, max_steps, policy.reprs)
    status = read_json(run_dir / "status.json") or {}
    meta = {"interval": strip.interval, "frame_steps": rec.frame_steps, "episode_return": rec.episode_return,
            "steps_to_goal": rec.length if strip.goal and rec.terminated else None,
            "episode_length": rec.length, "terminated": rec.terminated, "checkpoint": policy.checkpoint,
            "run_status": status.get("state"), "run_config_hash": status.get("config_hash"),
            "max_steps": max_steps or None, "settings": strip.settings()}
    output = RunOutput(out) if out else Run(run_dir).output("filmstrip")
    frames = npz_bytes({"frames": np.stack(rec.frames), "frame_steps": np.asarray(rec.frame_steps, dtype=np.int64)})
    # filmstrip.json after the frames, as before markers: a strip with both files is complete
    output.write(strip.output_hash(meta["run_config_hash"], meta["run_status"], max_steps),
                 {"frames.npz": frames, "filmstrip.json": meta})
    return meta
