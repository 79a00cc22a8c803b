"""Schemas of a task and of its representations V_s and V_a (``env/``, ``repr/state/``, ``repr/action/``)."""
from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from plls_bench.config.checks import Validated, check, check_choice, check_fraction, check_nonnegative, check_positive

ENV_NAMES = ("mountaincar", "carracing", "cheetah")
REPR_KINDS = ("none", "vae")
DATA_POLICIES = ("uniform", "correlated")
ENV_BACKENDS = ("gymnasium", "envpool")
# How a dm_control task looks: its own textures, or the DBC reference code's copy of the suite
# (plls_bench.envs.dmc.DBC_REFERENCE_LOOK; docs/decisions.md#d22)
ENV_VISUALS = ("stock", "dbc_reference")
RESTYLED_TASKS = ("cheetah",)  # the dm_control tasks env.visuals restyles; it means nothing elsewhere
# gymnasium ids envpool ships (plls_bench.envs.envpool_backend.ENVPOOL_TASKS; kept here so that
# validating a config never imports the engine)
ENVPOOL_GYM_IDS = ("CarRacing-v3", "MountainCarContinuous-v0")


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
    backend: str = "gymnasium"
    backend_threads: int = 0
    visuals: str = "stock"

    def validate_backend(self) -> None:
        check_choice(self.backend, ENV_BACKENDS, "env.backend")
        check(self.backend != "envpool" or self.gym_id in ENVPOOL_GYM_IDS, "env.backend",
              f"envpool has no task {self.gym_id!r} (env.name={self.name}); it ships "
              f"{', '.join(ENVPOOL_GYM_IDS)}: use env.backend=gymnasium")
        check_nonnegative(self.backend_threads, "env.backend_threads")

    def validate(self) -> None:
        check_choice(self.name, ENV_NAMES, "env.name")
        check_positive(self.max_episode_steps, "env.max_episode_steps")
        check_positive(self.frame_stack, "env.frame_stack")
        check_positive(self.action_repeat, "env.action_repeat")
        check_nonnegative(self.camera_id, "env.camera_id")
        check_positive(self.data_num_envs, "env.data_num_envs")
        check_fraction(self.data_train_fraction, "env.data_train_fraction")
        check_choice(self.data_policy, DATA_POLICIES, "env.data_policy")
        self.validate_backend()
        check_choice(self.visuals, ENV_VISUALS, "env.visuals")
        check(self.visuals == "stock" or self.name in RESTYLED_TASKS, "env.visuals",
              f"{self.visuals!r} restyles a dm_control task; env.name={self.name} is not one: use env.visuals=stock")
        check(0 <= self.data_policy_correlation < 1, "env.data_policy_correlation",
              f"must be in [0, 1), got {self.data_policy_correlation!r}")
        if self.pixels or self.data_pixels:
            check_positive(self.image_size, "env.image_size")


# --------------------------------------------------------------------------- representations
def conv_sizes(size: int, kernels: list[int], strides: list[int]) -> list[int]:
    """Spatial sizes through unpadded convolutions: ``[size, after conv 1, ...]``."""
    sizes = [size]
    for kernel, stride in zip(kernels, strides):
        sizes.append((sizes[-1] - kernel) // stride + 1)
    return sizes


@dataclass
class StateReprConfig(Validated):
    """V_s: convolutional VAE over image observations (World Models style).

    The encoder is ``len(channels)`` stride-2 convolutions (no padding) with ReLU; the decoder maps
    z to the encoder's last feature map and mirrors it with stride-2 transposed convolutions whose
    kernels must bring the image back to its exact size (checked against ``env.image_size``).
    Values live in ``conf/repr/state/`` (per task in ``per_env/``), each with its source.
    """

    kind: str = MISSING
    latent_dim: int = MISSING
    channels: list[int] = MISSING
    kernel_sizes: list[int] = MISSING
    deconv_kernel_sizes: list[int] = MISSING
    kl_weight: float = MISSING
    likelihood_std: float = MISSING
    learning_rate: float = MISSING
    batch_size: int = MISSING
    val_fraction: float = MISSING

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
        return conv_sizes(image_size, list(self.kernel_sizes), [2] * len(self.kernel_sizes))

    def decoded_size(self, image_size: int) -> int:
        """Spatial size the transposed convolutions produce from the last feature map."""
        size = self.feature_sizes(image_size)[-1]
        for kernel in self.deconv_kernel_sizes:
            size = (size - 1) * 2 + kernel
        return size


VAE_ACTIVATIONS = ("relu", "elu", "tanh")  # repr/models.py builds these


@dataclass
class ActionReprConfig(Validated):
    """V_a: MLP VAE over actions; its frozen decoder maps the policy's latent e to an action.
    Values live in ``conf/repr/action/`` (per task in ``per_env/``), each with its source."""

    kind: str = MISSING
    latent_dim: int = MISSING
    encoder_hidden: list[int] = MISSING
    decoder_hidden: list[int] = MISSING
    activation: str = MISSING
    kl_weight: float = MISSING
    likelihood_std: float = MISSING
    learning_rate: float = MISSING
    batch_size: int = MISSING
    val_fraction: float = MISSING
    latent_action_bound: float = MISSING

    def validate(self) -> None:
        check_choice(self.kind, REPR_KINDS, "repr.action.kind")
        check_positive(self.latent_dim, "repr.action.latent_dim")
        check_choice(self.activation, VAE_ACTIVATIONS, "repr.action.activation")
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
