"""Typed configuration: dataclass schemas registered in Hydra's ConfigStore.

Values live in ``conf/`` (yaml, every key commented with its source); this module holds only types,
defaults that are *not* paper settings, and validation. ``validate`` runs when Hydra's
``DictConfig`` is converted with ``OmegaConf.to_object`` (see :func:`to_config`), which the entry
point does before it creates a run directory or starts any compute. Errors name the offending key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

ENV_NAMES = ("mountaincar", "carracing", "cheetah")
REPR_KINDS = ("none", "vae")
ALGO_NAMES = ("ppo", "dbc", "none")
BUDGET_NAMES = ("smoke", "quick", "paper")
DATA_POLICIES = ("uniform", "correlated")
FEATURE_EXTRACTORS = ("mlp", "paper_cnn")
ACTIVATIONS = ("tanh", "relu")


class ConfigError(ValueError):
    """A config value is invalid; the message names the key."""


def check(ok: bool, key: str, message: str) -> None:
    """Raise :class:`ConfigError` naming ``key`` unless ``ok``."""
    if not ok:
        raise ConfigError(f"{key}: {message}")


def check_positive(value: float, key: str) -> None:
    check(isinstance(value, (int, float)) and math.isfinite(value) and value > 0, key,
          f"must be > 0, got {value!r}")


def check_nonnegative(value: float, key: str) -> None:
    check(isinstance(value, (int, float)) and math.isfinite(value) and value >= 0, key,
          f"must be >= 0, got {value!r}")


def check_choice(value: str, choices: tuple[str, ...], key: str) -> None:
    check(value in choices, key, f"unknown value {value!r}; choose one of {', '.join(choices)}")


def check_fraction(value: float, key: str, *, open_right: bool = True) -> None:
    upper_ok = value < 1 if open_right else value <= 1
    check(0 < value and upper_ok, key, f"must be in (0, 1{')' if open_right else ']'}, got {value!r}")


class Validated:
    """Runs :meth:`validate` after construction, once every field has a value.

    OmegaConf instantiates schemas with ``???`` placeholders when it registers them; those
    instances are templates, not configs, so they are not validated. A config converted with
    ``OmegaConf.to_object`` has no placeholders left (OmegaConf refuses missing values first).
    """

    def __post_init__(self) -> None:
        if not any(getattr(self, f.name) == MISSING for f in fields(self)):  # type: ignore[arg-type]
            self.validate()

    def validate(self) -> None:
        """Check value ranges and choices; raise :class:`ConfigError` naming the key."""


# --------------------------------------------------------------------------- environments
@dataclass
class EnvConfig(Validated):
    """One task: a gymnasium id or dm_control domain-task, and its observation settings."""

    name: str = MISSING
    gym_id: str = MISSING
    max_episode_steps: int = MISSING
    pixels: bool = False
    image_size: int = 0
    frame_stack: int = 1
    action_repeat: int = 1
    camera_id: int = 0
    data_pixels: bool = False
    data_num_envs: int = 1
    data_async: bool = False
    data_train_fraction: float = MISSING
    data_policy: str = "uniform"
    data_policy_correlation: float = 0.95

    def validate(self) -> None:
        check_choice(self.name, ENV_NAMES, "env.name")
        check_positive(self.max_episode_steps, "env.max_episode_steps")
        check_positive(self.frame_stack, "env.frame_stack")
        check_positive(self.action_repeat, "env.action_repeat")
        check_positive(self.data_num_envs, "env.data_num_envs")
        check_fraction(self.data_train_fraction, "env.data_train_fraction")
        check_choice(self.data_policy, DATA_POLICIES, "env.data_policy")
        check(0 <= self.data_policy_correlation < 1, "env.data_policy_correlation",
              f"must be in [0, 1), got {self.data_policy_correlation!r}")
        if self.pixels or self.data_pixels:
            check_positive(self.image_size, "env.image_size")


# --------------------------------------------------------------------------- representations
@dataclass
class StateReprConfig(Validated):
    """V_s: convolutional VAE over image observations (World Models style).

    The encoder is ``len(channels)`` stride-2 convolutions (no padding) with ReLU; the decoder maps
    z to the encoder's last feature map and mirrors it with stride-2 transposed convolutions whose
    kernels must bring the image back to its exact size (checked against ``env.image_size``).
    """

    kind: str = "none"
    latent_dim: int = 32
    channels: list[int] = field(default_factory=lambda: [32, 64, 128, 256])
    kernel_sizes: list[int] = field(default_factory=lambda: [4, 4, 4, 4])
    deconv_kernel_sizes: list[int] = field(default_factory=lambda: [4, 4, 5, 4])
    kl_weight: float = 1.0
    likelihood_std: float = 0.7071067811865476
    learning_rate: float = 1e-4
    batch_size: int = 100
    val_fraction: float = 0.1

    def validate(self) -> None:
        check_choice(self.kind, REPR_KINDS, "repr.state.kind")
        check_positive(self.latent_dim, "repr.state.latent_dim")
        check_nonnegative(self.kl_weight, "repr.state.kl_weight")
        check_positive(self.likelihood_std, "repr.state.likelihood_std")
        check_positive(self.learning_rate, "repr.state.learning_rate")
        check_positive(self.batch_size, "repr.state.batch_size")
        check_fraction(self.val_fraction, "repr.state.val_fraction")
        check(len(self.channels) > 0, "repr.state.channels", "needs at least one conv layer")
        check(len(self.channels) == len(self.kernel_sizes), "repr.state.kernel_sizes",
              "needs one kernel size per entry of repr.state.channels")
        check(len(self.deconv_kernel_sizes) == len(self.channels), "repr.state.deconv_kernel_sizes",
              "needs one kernel size per entry of repr.state.channels")
        for i, width in enumerate(self.channels):
            check_positive(width, f"repr.state.channels[{i}]")
        for name in ("kernel_sizes", "deconv_kernel_sizes"):
            for i, size in enumerate(getattr(self, name)):
                check_positive(size, f"repr.state.{name}[{i}]")

    def feature_sizes(self, image_size: int) -> list[int]:
        """Spatial sizes through the encoder: ``[image_size, ..., last feature map]``."""
        sizes = [image_size]
        for kernel in self.kernel_sizes:
            sizes.append((sizes[-1] - kernel) // 2 + 1)
        return sizes

    def decoded_size(self, image_size: int) -> int:
        """Spatial size the transposed convolutions produce from the last feature map."""
        size = self.feature_sizes(image_size)[-1]
        for kernel in self.deconv_kernel_sizes:
            size = (size - 1) * 2 + kernel
        return size


ACTIVATIONS = ("relu", "elu", "tanh")


@dataclass
class ActionReprConfig(Validated):
    """V_a: MLP VAE over actions; its frozen decoder maps the policy's latent e to an action."""

    kind: str = "none"
    latent_dim: int = 3
    encoder_hidden: list[int] = field(default_factory=lambda: [32, 16, 8])
    decoder_hidden: list[int] = field(default_factory=lambda: [8, 16, 32])
    activation: str = "relu"
    kl_weight: float = 1.0
    likelihood_std: float = 0.1
    learning_rate: float = 1e-3
    batch_size: int = 64
    val_fraction: float = 0.1
    latent_action_bound: float = 3.0

    def validate(self) -> None:
        check_choice(self.kind, REPR_KINDS, "repr.action.kind")
        check_positive(self.latent_dim, "repr.action.latent_dim")
        check_choice(self.activation, ACTIVATIONS, "repr.action.activation")
        check_nonnegative(self.kl_weight, "repr.action.kl_weight")
        check_positive(self.likelihood_std, "repr.action.likelihood_std")
        check_positive(self.learning_rate, "repr.action.learning_rate")
        check_positive(self.batch_size, "repr.action.batch_size")
        check_fraction(self.val_fraction, "repr.action.val_fraction")
        check_positive(self.latent_action_bound, "repr.action.latent_action_bound")
        for name in ("encoder_hidden", "decoder_hidden"):
            for i, width in enumerate(getattr(self, name)):
                check_positive(width, f"repr.action.{name}[{i}]")


@dataclass
class ReprConfig(Validated):
    """Both representations and how trials share them. Default: one dataset and one model per
    task, shared by all trials (the paper's offline phase). ``per_trial_training``: every trial
    trains its own model on the shared dataset (trial 0's is the shared one). ``per_trial``:
    every trial also collects its own dataset."""

    state: StateReprConfig = field(default_factory=StateReprConfig)
    action: ActionReprConfig = field(default_factory=ActionReprConfig)
    per_trial: bool = False
    per_trial_training: bool = False


# --------------------------------------------------------------------------- algorithms
@dataclass
class PPOConfig(Validated):
    """stable-baselines3 PPO settings (Tables 1 and 2 of the paper) and the shared policy/value net.

    The paper's networks share one trunk between policy and value (Sec. 5.1, 5.2). In SB3 that is a
    features extractor shared by actor and critic with linear heads: ``mlp`` is an MLP of
    ``policy_hidden`` on vector observations; ``paper_cnn`` is ``cnn_channels`` conv layers
    followed by ``cnn_hidden`` fully connected layers on (C, H, W) images.
    """

    n_steps: int = MISSING
    learning_rate: float = MISSING
    n_epochs: int = MISSING
    batch_size: int = MISSING
    n_envs: int = MISSING
    gamma: float = MISSING
    gae_lambda: float = MISSING
    clip_range: float = MISSING
    vf_coef: float = MISSING
    ent_coef: float = MISSING
    max_grad_norm: float = 0.5
    features_extractor: str = "mlp"
    policy_hidden: list[int] = field(default_factory=lambda: [64, 64])
    activation: str = "tanh"
    cnn_channels: list[int] = field(default_factory=lambda: [32, 64, 128, 256])
    cnn_kernel_sizes: list[int] = field(default_factory=lambda: [4, 4, 4, 4])
    cnn_stride: int = 2
    cnn_hidden: list[int] = field(default_factory=lambda: [32, 32])
    log_std_init: float = 0.0
    ortho_init: bool = True
    vec_env: str = "dummy"
    eval_envs: int = 1

    @property
    def steps_per_iteration(self) -> int:
        """Env steps of one PPO iteration (one rollout and update): ``n_envs * n_steps``."""
        return self.n_envs * self.n_steps

    def validate(self) -> None:
        for key in ("n_steps", "learning_rate", "n_epochs", "n_envs", "max_grad_norm", "cnn_stride",
                    "eval_envs"):
            check_positive(getattr(self, key), f"algo.ppo.{key}")
        check(isinstance(self.batch_size, int) and self.batch_size > 1, "algo.ppo.batch_size",
              f"must be an int > 1 (SB3 normalises advantages per minibatch), got {self.batch_size!r}")
        check(self.batch_size <= self.steps_per_iteration, "algo.ppo.batch_size",
              f"{self.batch_size} exceeds the rollout of algo.ppo.n_envs x algo.ppo.n_steps = "
              f"{self.steps_per_iteration}")
        check_fraction(self.gamma, "algo.ppo.gamma", open_right=False)
        check_fraction(self.gae_lambda, "algo.ppo.gae_lambda", open_right=False)
        check_positive(self.clip_range, "algo.ppo.clip_range")
        check_nonnegative(self.vf_coef, "algo.ppo.vf_coef")
        check_nonnegative(self.ent_coef, "algo.ppo.ent_coef")
        check_choice(self.features_extractor, FEATURE_EXTRACTORS, "algo.ppo.features_extractor")
        check_choice(self.activation, ACTIVATIONS, "algo.ppo.activation")
        check_choice(self.vec_env, ("dummy", "subproc"), "algo.ppo.vec_env")
        check(len(self.cnn_kernel_sizes) == len(self.cnn_channels), "algo.ppo.cnn_kernel_sizes",
              "needs one kernel size per entry of algo.ppo.cnn_channels")
        for name in ("policy_hidden", "cnn_channels", "cnn_kernel_sizes", "cnn_hidden"):
            for i, width in enumerate(getattr(self, name)):
                check_positive(width, f"algo.ppo.{name}[{i}]")


TRANSITION_MODELS = ("deterministic", "probabilistic")


@dataclass
class DBCConfig(Validated):
    """Deep Bisimulation for Control (Zhang et al., ICLR 2021): SAC + bisimulation encoder.

    Values live in ``conf/algo/dbc.yaml`` with the reference flag each comes from
    (facebookresearch/deep_bisim4control, ``train.py`` and the ``run_*.sh`` launchers).
    """

    transition_model: str = MISSING
    hidden_dim: int = MISSING
    batch_size: int = MISSING
    discount: float = MISSING
    init_steps: int = MISSING
    replay_capacity: int = MISSING
    encoder_feature_dim: int = MISSING
    num_layers: int = MISSING
    num_filters: int = MISSING
    encoder_lr: float = MISSING
    encoder_tau: float = MISSING
    critic_lr: float = MISSING
    critic_beta: float = MISSING
    critic_tau: float = MISSING
    critic_target_update_freq: int = MISSING
    actor_lr: float = MISSING
    actor_beta: float = MISSING
    actor_log_std_min: float = MISSING
    actor_log_std_max: float = MISSING
    actor_update_freq: int = MISSING
    init_temperature: float = MISSING
    alpha_lr: float = MISSING
    alpha_beta: float = MISSING
    decoder_lr: float = MISSING
    decoder_weight_lambda: float = MISSING
    model_hidden_dim: int = MISSING
    sigma_min: float = MISSING
    sigma_max: float = MISSING
    bisim_coef: float = MISSING

    def validate(self) -> None:
        check_choice(self.transition_model, TRANSITION_MODELS, "algo.dbc.transition_model")
        for key in ("hidden_dim", "batch_size", "replay_capacity", "encoder_feature_dim", "num_layers",
                    "num_filters", "encoder_lr", "critic_lr", "critic_target_update_freq", "actor_lr",
                    "actor_update_freq", "init_temperature", "alpha_lr", "decoder_lr",
                    "model_hidden_dim", "sigma_min"):
            check_positive(getattr(self, key), f"algo.dbc.{key}")
        for key in ("init_steps", "decoder_weight_lambda", "bisim_coef"):
            check_nonnegative(getattr(self, key), f"algo.dbc.{key}")
        check_fraction(self.discount, "algo.dbc.discount")
        for key in ("encoder_tau", "critic_tau"):
            check_fraction(getattr(self, key), f"algo.dbc.{key}", open_right=False)
        for key in ("critic_beta", "actor_beta", "alpha_beta"):
            value = getattr(self, key)
            check(0 <= value < 1, f"algo.dbc.{key}", f"must be in [0, 1), got {value!r}")
        check(self.actor_log_std_min < self.actor_log_std_max, "algo.dbc.actor_log_std_min",
              f"must be < algo.dbc.actor_log_std_max ({self.actor_log_std_max}), got {self.actor_log_std_min}")
        check(self.sigma_min < self.sigma_max, "algo.dbc.sigma_min",
              f"must be < algo.dbc.sigma_max ({self.sigma_max}), got {self.sigma_min}")


@dataclass
class AlgoConfig(Validated):
    name: str = "none"
    ppo: Optional[PPOConfig] = None
    dbc: Optional[DBCConfig] = None

    def validate(self) -> None:
        check_choice(self.name, ALGO_NAMES, "algo.name")
        if self.name != "none":
            check(getattr(self, self.name) is not None, f"algo.{self.name}",
                  f"algo.name={self.name} needs an algo.{self.name} section")


# --------------------------------------------------------------------------- budgets
@dataclass
class BudgetConfig(Validated):
    """How much compute a run gets; smoke/quick/paper profiles, specialised per task."""

    name: str = MISSING
    trials: int = MISSING
    data_episodes: int = MISSING
    data_steps_per_episode: int = MISSING
    repr_epochs: int = MISSING
    repr_action_epochs: Optional[int] = None  # V_a epochs when set; None: repr_epochs
    train_env_steps: int = MISSING
    eval_every_env_steps: int = MISSING
    eval_episodes: int = MISSING
    eval_max_steps: int = 0  # cap on a test episode's agent steps; 0 = the env's own time limit

    def validate(self) -> None:
        check_choice(self.name, BUDGET_NAMES, "budget.name")
        for key in ("trials", "data_episodes", "data_steps_per_episode", "repr_epochs",
                    "train_env_steps", "eval_every_env_steps", "eval_episodes"):
            check_positive(getattr(self, key), f"budget.{key}")
        check_nonnegative(self.eval_max_steps, "budget.eval_max_steps")
        if self.repr_action_epochs is not None:
            check_positive(self.repr_action_epochs, "budget.repr_action_epochs")

    def epochs_for(self, which: str) -> int:
        """Training epochs of V_s (``state``) or V_a (``action``). V_a may get its own count:
        an epoch of it costs about a thousandth of a V_s epoch on the same data."""
        if which == "action" and self.repr_action_epochs is not None:
            return self.repr_action_epochs
        return self.repr_epochs


# --------------------------------------------------------------------------- studies
STUDY_NAMES = ("multistep", "onestep", "generalisation")
LATENT_CHOICES = ("e", "mu")
# MountainCarContinuous-v0's bounds (gymnasium): the studies set its state and act in its box.
MOUNTAINCAR_POSITION, MOUNTAINCAR_SPEED, MOUNTAINCAR_ACTION = (-1.2, 0.6), 0.07, (-1.0, 1.0)


@dataclass
class StudyConfig(Validated):
    """A MountainCar latent-space study (Figs 7-9, Sec. 5.1): which actions, from which state.

    ``multistep`` applies the actions one after another from ``s0`` (a trajectory); ``onestep``
    and ``generalisation`` apply each action for one step from ``s0``. Actions are drawn
    uniformly, ``actions_per_range`` from each ``action_ranges`` entry in order; the end of a
    range nearer to zero is open, so ``[-1, 0]`` and ``[0, 1]`` give the paper's [-1, 0) and (0, 1].
    """

    name: str = MISSING
    s0: list[float] = MISSING
    action_ranges: list[list[float]] = MISSING
    actions_per_range: int = MISSING
    samples_per_action: int = 1
    decode: str = "e"
    knn: int = 10
    tracking_tolerance: float = 0.05

    def validate(self) -> None:
        check_choice(self.name, STUDY_NAMES, "study.name")
        check(len(self.s0) == 2, "study.s0", f"must be (x, x_dot), got {list(self.s0)}")
        low, high = MOUNTAINCAR_POSITION
        check(low <= self.s0[0] <= high, "study.s0", f"x = {self.s0[0]} is outside [{low}, {high}]")
        check(abs(self.s0[1]) <= MOUNTAINCAR_SPEED, "study.s0",
              f"x_dot = {self.s0[1]} is outside [-{MOUNTAINCAR_SPEED}, {MOUNTAINCAR_SPEED}]")
        check(len(self.action_ranges) > 0, "study.action_ranges", "needs at least one [low, high]")
        for i, bounds in enumerate(self.action_ranges):
            check(len(bounds) == 2 and MOUNTAINCAR_ACTION[0] <= bounds[0] < bounds[1] <= MOUNTAINCAR_ACTION[1],
                  f"study.action_ranges[{i}]", f"must be [low, high] with {MOUNTAINCAR_ACTION[0]} <= low < "
                  f"high <= {MOUNTAINCAR_ACTION[1]}, got {list(bounds)}")
        check_positive(self.actions_per_range, "study.actions_per_range")
        check_positive(self.samples_per_action, "study.samples_per_action")
        check_choice(self.decode, LATENT_CHOICES, "study.decode")
        check_positive(self.knn, "study.knn")
        check_positive(self.tracking_tolerance, "study.tracking_tolerance")
        if self.name == "generalisation":
            check(self.decode == "e", "study.decode", "generalisation decodes its samples e; mu is one point")
        else:  # the README's arrays hold one e per action for these studies
            check(self.samples_per_action == 1, "study.samples_per_action", f"{self.name} takes one e per action")
        check(self.knn < self.n_actions, "study.knn", f"must be < the {self.n_actions} actions")

    @property
    def n_actions(self) -> int:
        return len(self.action_ranges) * self.actions_per_range


@dataclass
class FilmstripConfig(Validated):
    """A filmstrip of a trained policy (Figs 11, 19, 22): one evaluation episode, a frame every
    ``interval`` env frames (steps counting action repeat), and its last frame.

    ``python -m plls_bench.analysis.filmstrip RUN_DIR`` composes ``conf/filmstrip/<env>.yaml``.
    """

    interval: int = MISSING
    reset_options: dict[str, float] = field(default_factory=dict)
    goal: bool = False
    episode: int = 0
    frame_height: int = 200

    def validate(self) -> None:
        check_positive(self.interval, "filmstrip.interval")
        check(isinstance(self.episode, int) and self.episode >= 0, "filmstrip.episode",
              f"must be a non-negative int, got {self.episode!r}")
        check_positive(self.frame_height, "filmstrip.frame_height")


# --------------------------------------------------------------------------- root
RUNNERS = ("collect", "repr", "ppo", "dbc", "study")


@dataclass
class Config(Validated):
    """One run: what to run (runner, experiment), on which task, with which seed and budget."""

    experiment: str = "adhoc"
    variant: str = "auto"
    runner: str = "collect"
    seed: int = 0
    data_seed: int = 0
    runs_dir: str = "results/runs"
    device: str = "cpu"
    torch_threads: int = 0
    progress: bool = True
    env: EnvConfig = field(default_factory=EnvConfig)
    repr: ReprConfig = field(default_factory=ReprConfig)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    budget: BudgetConfig = field(default_factory=BudgetConfig)
    study: Optional[StudyConfig] = None
    filmstrip: Optional[FilmstripConfig] = None

    def validate(self) -> None:
        check_choice(self.runner, RUNNERS, "runner")
        check(self.seed >= 0, "seed", f"must be a non-negative int, got {self.seed!r}")
        check(self.data_seed >= 0, "data_seed", f"must be a non-negative int, got {self.data_seed!r}")
        check_choice(self.device, ("cpu", "cuda", "auto"), "device")
        check_nonnegative(self.torch_threads, "torch_threads")
        check(bool(self.experiment) and "/" not in self.experiment, "experiment",
              f"must be a non-empty name without '/', got {self.experiment!r}")
        check("/" not in self.variant, "variant", f"must not contain '/', got {self.variant!r}")
        if self.runner in ("ppo", "dbc"):
            check(self.algo.name == self.runner, "algo",
                  f"runner={self.runner} needs algo={self.runner}, got algo.name={self.algo.name}")
        if self.runner == "ppo" and self.algo.ppo is not None:
            self._check_ppo_network(self.algo.ppo)
        if self.runner == "repr":
            check("vae" in (self.repr.state.kind, self.repr.action.kind), "repr",
                  "runner=repr needs repr/state=vae or repr/action=vae (both are none)")
        if self.repr.state.kind == "vae":
            self._validate_state_vae()
        if self.runner == "study":
            check(self.study is not None, "study", "runner=study needs a study section (+study=NAME)")
            check(self.env.name == "mountaincar", "env", f"the studies are MountainCar's, got env {self.env.name}")
            check(self.repr.action.kind == "vae", "repr.action.kind", "runner=study needs repr/action=vae")

    def _validate_state_vae(self) -> None:
        """V_s needs stored single frames, and its decoder must rebuild the frame's exact size."""
        state, size = self.repr.state, self.env.image_size
        check(self.env.data_pixels and self.env.frame_stack == 1, "repr.state.kind",
              f"vae needs single-frame pixel data; env {self.env.name} has data_pixels="
              f"{self.env.data_pixels}, frame_stack={self.env.frame_stack}")
        sizes = state.feature_sizes(size)
        check(sizes[-1] >= 1, "repr.state.kernel_sizes",
              f"shrink a {size}x{size} image to nothing: spatial sizes {sizes}")
        check(state.decoded_size(size) == size, "repr.state.deconv_kernel_sizes",
              f"{state.deconv_kernel_sizes} decode the {sizes[-1]}x{sizes[-1]} feature map to "
              f"{state.decoded_size(size)}x{state.decoded_size(size)}, not {size}x{size}")

    def _check_ppo_network(self, ppo: PPOConfig) -> None:
        """The policy's trunk must fit what it sees: images unless V_s encodes them."""
        images = self.env.pixels and self.repr.state.kind == "none"
        want = "paper_cnn" if images else "mlp"
        seen = "images" if images else "vectors"
        check(ppo.features_extractor == want, "algo.ppo.features_extractor",
              f"{ppo.features_extractor} does not fit the policy's observations ({seen}: env={self.env.name}, "
              f"repr.state={self.repr.state.kind}); use {want}")


def register_configs() -> None:
    """Register the root schema; conf/config.yaml lists it first in its defaults."""
    ConfigStore.instance().store(name="plls_schema", node=Config)


def to_config(cfg: DictConfig | Config) -> Config:
    """Convert Hydra's DictConfig to the typed :class:`Config` (runs every ``__post_init__``)."""
    if isinstance(cfg, Config):
        return cfg
    try:
        obj: Any = OmegaConf.to_object(cfg)
    except ConfigError:
        raise
    except Exception as err:  # OmegaConf's own errors: missing values, wrong types
        raise ConfigError(_omegaconf_message(err)) from err
    assert isinstance(obj, Config), f"expected Config, got {type(obj).__name__}"
    return obj


def _omegaconf_message(err: Exception) -> str:
    """First line of an OmegaConf error, prefixed by its full key when it names one."""
    key = getattr(err, "full_key", None)
    first = str(err).splitlines()[0] if str(err) else type(err).__name__
    return f"{key}: {first}" if key else first
