"""dm_control tasks as gymnasium envs: pixels (channel-first uint8), action repeat, frame stack.

A small wrapper rather than shimmy's, because it renders only the last physics step of each
action repeat (rendering dominates the cost on CPU) and stacks frames along the channel axis,
as the DBC reference code does.
"""
from __future__ import annotations

import logging
import xml.etree.ElementTree as ElementTree
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np

from plls_bench.envs.mujoco_gl import ensure_mujoco_gl

_SETTOTALMASS = "compiler attribute 'settotalmass' is deprecated"


class _DropSettotalmass(logging.Filter):
    """dm_control's cheetah.xml still sets ``<compiler settotalmass>``, which MuJoCo 3 deprecates;
    dm_control forwards MuJoCo's warning to absl's logger once per env built (every env of a
    vector env, every eval env), which buries the log. Only that message is dropped."""

    def filter(self, record: logging.LogRecord) -> bool:
        return _SETTOTALMASS not in record.getMessage()


logging.getLogger("absl").addFilter(_DropSettotalmass())

# ``env.visuals=dbc_reference``: the look of the DBC reference code's copy of the suite
# (facebookresearch/deep_bisim4control, local_dm_control_suite: cheetah.xml includes
# common/materials_white_floor.xml, a grey floor checker, and common/skybox.xml has black marks
# where dm_control's are white). Asset file -> texture name -> attributes set on it.
DBC_REFERENCE_LOOK: dict[str, dict[str, dict[str, str]]] = {
    "./common/materials.xml": {"grid": {"rgb1": ".1 .1 .1", "rgb2": ".2 .2 .2", "markrgb": ".1 .1 .1"}},
    "./common/skybox.xml": {"skybox": {"markrgb": "0 0 0"}},
}


def restyled_assets(assets: dict[str, bytes], look: dict[str, dict[str, dict[str, str]]]) -> dict[str, bytes]:
    """``assets`` (file -> XML) with the textures ``look`` names given its attributes; a texture it
    names that is missing is an error, so a dm_control release that renames one cannot pass unseen."""
    styled = dict(assets)
    for name, textures in look.items():
        root = ElementTree.fromstring(assets[name])
        for texture, attributes in textures.items():
            node = root.find(f".//texture[@name='{texture}']")
            if node is None:
                raise KeyError(f"{name} has no texture {texture!r} to restyle")
            node.attrib.update(attributes)
        styled[name] = ElementTree.tostring(root)
    return styled


class DMCEnv(gym.Env):
    """``domain-task`` from dm_control's suite with actions in [-1, 1]^n.

    Observations: ``(3 * frame_stack, size, size)`` uint8 pixels, or the flattened proprioceptive
    state (float32) when ``pixels=False``. An episode ends by truncation after ``max_episode_steps``
    control steps (frames, counting action repeat; ``env.max_episode_steps``), which replaces the
    task's own time limit (cheetah's: 1000), or at that limit when None. ``visuals``: ``stock``
    (dm_control's textures) or ``dbc_reference`` (:data:`DBC_REFERENCE_LOOK`; cheetah only).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, domain_task: str, *, pixels: bool = True, image_size: int = 84,
                 camera_id: int = 0, action_repeat: int = 1, frame_stack: int = 1,
                 max_episode_steps: int | None = None, render_mode: str | None = None,
                 visuals: str = "stock") -> None:
        ensure_mujoco_gl()  # even state-only: importing dm_control initialises a GL backend
        self.domain, self.task = domain_task.split("-", 1)
        if visuals not in ("stock", "dbc_reference") or (visuals != "stock" and self.domain != "cheetah"):
            raise ValueError(f"visuals={visuals!r}: stock, or dbc_reference for cheetah")
        self.visuals = visuals
        self.pixels, self.image_size, self.camera_id = pixels, image_size, camera_id
        self.action_repeat, self.frame_stack = action_repeat, frame_stack
        self.render_mode, self.max_episode_steps, self._steps = render_mode, max_episode_steps, 0
        self._env = self._load(seed=None)
        spec = self._env.action_spec()
        self._act_low, self._act_high = spec.minimum.astype(np.float64), spec.maximum.astype(np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=spec.shape, dtype=np.float32)
        if pixels:
            shape = (3 * frame_stack, image_size, image_size)
            self.observation_space = gym.spaces.Box(0, 255, shape=shape, dtype=np.uint8)
        else:
            dim = sum(int(np.prod(v.shape)) for v in self._env.observation_spec().values())
            self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)
        self._frames: deque[np.ndarray] = deque(maxlen=frame_stack)

    def _load(self, seed: int | None) -> Any:
        from dm_control import suite  # after ensure_mujoco_gl: mujoco reads MUJOCO_GL at import

        limit = {} if self.max_episode_steps is None else {"time_limit": float("inf")}  # counted in step
        if self.visuals == "stock":
            return suite.load(self.domain, self.task, task_kwargs={"random": seed, **limit})
        from dm_control.rl import control
        from dm_control.suite import cheetah

        xml, assets = cheetah.get_model_and_assets()  # what suite.load's cheetah.run builds, restyled
        physics = cheetah.Physics.from_xml_string(xml, restyled_assets(assets, DBC_REFERENCE_LOOK))
        return control.Environment(physics, cheetah.Cheetah(random=seed),
                                   time_limit=limit.get("time_limit", cheetah._DEFAULT_TIME_LIMIT))

    def _frame(self) -> np.ndarray:
        image = self._env.physics.render(self.image_size, self.image_size, camera_id=self.camera_id)
        return np.ascontiguousarray(image.transpose(2, 0, 1))

    def _observation(self, time_step: Any) -> np.ndarray:
        if not self.pixels:
            parts = [np.asarray(v, dtype=np.float32).ravel() for v in time_step.observation.values()]
            return np.concatenate(parts)
        return np.concatenate(list(self._frames), axis=0)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None:  # dm_control seeds its task RNG at load time
            self._env = self._load(seed)
        time_step, self._steps = self._env.reset(), 0
        if self.pixels:
            frame = self._frame()
            for _ in range(self.frame_stack):
                self._frames.append(frame)
        return self._observation(time_step), {}

    def step(self, action: np.ndarray):
        action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        scaled = self._act_low + (action + 1.0) * 0.5 * (self._act_high - self._act_low)
        reward, time_step = 0.0, None
        for _ in range(self.action_repeat):
            time_step, self._steps = self._env.step(scaled), self._steps + 1
            reward += time_step.reward or 0.0
            if time_step.last() or self._steps == self.max_episode_steps:
                break
        if self.pixels:
            self._frames.append(self._frame())
        truncated = bool(time_step.last()) or self._steps == self.max_episode_steps
        return self._observation(time_step), float(reward), False, truncated, {}

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        image = self._env.physics.render(self.image_size or 84, self.image_size or 84, camera_id=self.camera_id)
        return np.ascontiguousarray(image)

    def close(self) -> None:
        self._env = None
