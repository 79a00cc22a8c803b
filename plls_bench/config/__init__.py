"""Typed configuration: dataclass schemas registered in Hydra's ConfigStore.

Values live in ``conf/`` (yaml, every key commented with its source); this module holds only types,
defaults that are *not* paper settings, and validation. ``validate`` runs when Hydra's
``DictConfig`` is converted with ``OmegaConf.to_object`` (see :func:`to_config`), which the entry
point does before it creates a run directory or starts any compute. Errors name the offending key.

Validation checks what a config *is*, on any machine: recorded configs are validated again when
they are read back (reports, filmstrips). Whether this machine *has* the device a config asks for
is checked where a command is about to compute (:func:`plls_bench.rundirs.devices.require_device`, from the
CLI and the runners), so a run recorded with ``device=cuda`` stays readable on a CPU-only machine.

Layer ``config`` of tests/test_imports.py: imports only from itself and the layers below it
(``core``); no layer below imports it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from plls_bench.config.checks import (
    ConfigError,
    Validated,
    check,
    check_choice,
    check_fraction,
    check_nonnegative,
    check_positive,
)
from plls_bench.config.learning import (
    ALGO_NAMES,
    BUDGET_NAMES,
    DBC_ENCODERS,
    FEATURE_EXTRACTORS,
    PPO_ACTIVATIONS,
    TRANSITION_MODELS,
    AlgoConfig,
    BudgetConfig,
    DBCConfig,
    PPOConfig,
)
from plls_bench.config.runner_checks import RUNNER_CHECKS
from plls_bench.config.studies_film import LATENT_CHOICES, STUDY_NAMES, FilmstripConfig, StudyConfig
from plls_bench.config.tasks import (
    DATA_POLICIES,
    ENV_NAMES,
    REPR_KINDS,
    VAE_ACTIVATIONS,
    ActionReprConfig,
    EnvConfig,
    ReprConfig,
    StateReprConfig,
)

__all__ = ["ALGO_NAMES", "BUDGET_NAMES", "DATA_POLICIES", "DBC_ENCODERS", "DEVICES", "ENV_NAMES", "FEATURE_EXTRACTORS",
           "LATENT_CHOICES", "PPO_ACTIVATIONS", "PRECISIONS", "REPR_KINDS", "STUDY_NAMES", "TRANSITION_MODELS",
           "VAE_ACTIVATIONS",
           "ActionReprConfig", "AlgoConfig", "BudgetConfig", "Config", "ConfigError", "DBCConfig", "EnvConfig",
           "FilmstripConfig", "PPOConfig", "ReprConfig", "StateReprConfig", "StudyConfig", "Validated", "check",
           "check_choice", "check_fraction", "check_nonnegative", "check_positive", "register_configs", "to_config"]

# How the conv trunks compute (plls_bench/repr/pixel_trunk.py): fp32, or bf16 autocast around the trunks only.
PRECISIONS = ("fp32", "bf16")
# Where torch computes; plls_bench.rundirs.devices resolves the setting (auto: a CUDA GPU when torch sees one).
DEVICES = ("cpu", "cuda", "auto")


# --------------------------------------------------------------------------- root
@dataclass
class Config(Validated):
    """One run: what to run (runner, experiment), on which task, with which seed and budget."""

    experiment: str = "adhoc"
    variant: str = "auto"
    runner: str = "collect"
    seed: int = 0
    data_seed: int = 0
    runs_dir: str = "results/runs"
    device: str = "auto"
    torch_threads: int = 0
    retain_freed_memory: bool = True
    precision: str = "fp32"
    progress: bool = True
    time_limit_min: float = 0.0
    env: EnvConfig = field(default_factory=EnvConfig)
    repr: ReprConfig = field(default_factory=ReprConfig)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    budget: BudgetConfig = field(default_factory=BudgetConfig)
    study: Optional[StudyConfig] = None
    filmstrip: Optional[FilmstripConfig] = None

    def validate(self) -> None:
        check_choice(self.runner, tuple(RUNNER_CHECKS), "runner")
        check(self.seed >= 0, "seed", f"must be a non-negative int, got {self.seed!r}")
        check(self.data_seed >= 0, "data_seed", f"must be a non-negative int, got {self.data_seed!r}")
        check_choice(self.device, DEVICES, "device")
        check_choice(self.precision, PRECISIONS, "precision")
        check_nonnegative(self.torch_threads, "torch_threads")
        check_nonnegative(self.time_limit_min, "time_limit_min")
        check(bool(self.experiment) and "/" not in self.experiment, "experiment",
              f"must be a non-empty name without '/', got {self.experiment!r}")
        check("/" not in self.variant, "variant", f"must not contain '/', got {self.variant!r}")
        if self.repr.state.kind == "vae":
            self._validate_state_vae()
        RUNNER_CHECKS[self.runner](self)  # the runner's own checks (plls_bench/config/runner_checks.py)

    def _validate_state_vae(self) -> None:
        """V_s needs stored single frames, and its decoder must rebuild the frame's exact size."""
        state, size = self.repr.state, self.env.image_size
        check(self.env.data_pixels and self.env.frame_stack == 1, "repr.state.kind",
              f"vae needs single-frame pixel data; env {self.env.name} has data_pixels="
              f"{self.env.data_pixels}, frame_stack={self.env.frame_stack}")
        sizes = state.feature_sizes(size)
        check(min(sizes) >= 1, "repr.state.kernel_sizes",
              f"shrink a {size}x{size} image (env.image_size) to nothing: spatial sizes {sizes}")
        check(state.decoded_size(size) == size, "repr.state.deconv_kernel_sizes",
              f"{state.deconv_kernel_sizes} decode the {sizes[-1]}x{sizes[-1]} feature map to "
              f"{state.decoded_size(size)}x{state.decoded_size(size)}, not {size}x{size}")


def register_configs() -> None:
    """Register the root schema; conf/config.yaml lists it first in its defaults."""
    ConfigStore.instance().store(name="plls_schema", node=Config)


def to_config(cfg: DictConfig | Config) -> Config:
    """Convert Hydra's DictConfig to the typed :class:`Config` (runs every ``__post_init__``)."""
    if isinstance(cfg, Config):
        return cfg
    _check_repr_architectures(cfg)
    try:
        obj: Any = OmegaConf.to_object(cfg)
    except ConfigError:
        raise
    except Exception as err:  # OmegaConf's own errors: missing values, wrong types
        raise ConfigError(_omegaconf_message(err)) from err
    assert isinstance(obj, Config), f"expected Config, got {type(obj).__name__}"
    return obj


def _check_repr_architectures(cfg: DictConfig) -> None:
    """A VAE switched on for a task without an architecture file of its own leaves the schema's
    required keys unset: name the choice and the file, not just the first unset key."""
    for part in ("state", "action"):
        node = OmegaConf.select(cfg, f"repr.{part}")
        if not isinstance(node, DictConfig) or OmegaConf.is_missing(node, "kind") or node.kind == "none":
            continue
        unset = [key for key in node if OmegaConf.is_missing(node, key)]
        env = OmegaConf.select(cfg, "env.name")
        check(not unset, f"repr.{part}.kind", f"{node.kind} has no architecture for env {env} "
              f"(conf/repr/{part}/per_env/{node.kind}_{env}.yaml); unset: {', '.join(map(str, unset))}")


def _omegaconf_message(err: Exception) -> str:
    """First line of an OmegaConf error, prefixed by its full key when it names one."""
    key = getattr(err, "full_key", None)
    first = str(err).splitlines()[0] if str(err) else type(err).__name__
    return f"{key}: {first}" if key else first
