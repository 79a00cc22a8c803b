"""Each runner's own config checks, and :data:`RUNNER_CHECKS`: the runners a config may name.

Kept in the config layer (no torch, no simulators): ``Config.validate`` looks the runner up in
:data:`RUNNER_CHECKS` and runs its checks on every composed or recorded config. The runner registry
(``plls_bench/pipeline/runner_registry.py``) sits above this layer; a test keeps its names and this table's
the same. Each check raises :class:`ConfigError` with one line naming the offending key.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Optional, Protocol

from plls_bench.config.checks import check
from plls_bench.config.learning import AlgoConfig
from plls_bench.config.studies_film import StudyConfig
from plls_bench.config.tasks import EnvConfig, ReprConfig, conv_sizes


def runner_of(algo_name: str, otherwise: str) -> str:
    """The runner a config runs unless it names one (``runner:`` in conf/config.yaml): a policy
    learner's runner is named after its algorithm (:func:`_check_algo`), so ``override /algo``
    alone picks it; a config without one (``algo.name`` none) runs ``otherwise``."""
    return otherwise if algo_name == "none" else algo_name


class RunnerConfig(Protocol):
    """What the checks read of the root ``Config`` (which imports this module, so it is not imported here)."""

    runner: str
    env: EnvConfig
    repr: ReprConfig
    algo: AlgoConfig
    study: Optional[StudyConfig]


def validate_collect(cfg: RunnerConfig) -> None:
    """``collect`` stores random-policy data: it learns no policy."""
    _check_no_algo(cfg)


def validate_repr(cfg: RunnerConfig) -> None:
    """``repr`` trains V_s and/or V_a (at least one must be a VAE), no policy."""
    _check_no_algo(cfg)
    check("vae" in (cfg.repr.state.kind, cfg.repr.action.kind), "repr",
          "runner=repr needs repr/state=vae or repr/action=vae (both are none)")


def validate_study(cfg: RunnerConfig) -> None:
    """The latent-space studies are MountainCar's and probe V_a; they learn no policy."""
    _check_no_algo(cfg)
    check(cfg.study is not None, "study", "runner=study needs a study section (+study=NAME)")
    check(cfg.env.name == "mountaincar", "env", f"the studies are MountainCar's, got env {cfg.env.name}")
    check(cfg.repr.action.kind == "vae", "repr.action.kind", "runner=study needs repr/action=vae")


def validate_ppo(cfg: RunnerConfig) -> None:
    """PPO needs its algo section, a trunk that fits what the policy sees, and convs that fit the frames."""
    _check_algo(cfg, "ppo")
    ppo = cfg.algo.ppo
    if ppo is None:
        return
    images = cfg.env.pixels and cfg.repr.state.kind == "none"
    want, seen = ("paper_cnn", "images") if images else ("mlp", "vectors")
    fits = ppo.features_extractor == want or (not images and ppo.features_extractor == "separate_mlp")
    check(fits, "algo.ppo.features_extractor",
          f"{ppo.features_extractor} does not fit the policy's observations ({seen}: env={cfg.env.name}, "
          f"repr.state={cfg.repr.state.kind}); use {want}")
    # With V_s the policy sees vectors and has no conv stack (V_s's own convs are checked by Config).
    if cfg.env.pixels and ppo.features_extractor == "paper_cnn":
        size, kernels = cfg.env.image_size, list(ppo.cnn_kernel_sizes)
        sizes = conv_sizes(size, kernels, [ppo.cnn_stride] * len(kernels))
        check(min(sizes) >= 1, "env.image_size",
              f"{size}x{size} frames are too small for the policy's convs (algo.ppo.cnn_kernel_sizes="
              f"{kernels}, algo.ppo.cnn_stride={ppo.cnn_stride}): spatial sizes {sizes}")


def validate_dbc(cfg: RunnerConfig) -> None:
    """DBC needs its algo section and an encoder that leaves at least a 1x1 feature map; state
    SAC (``algo.dbc.encoder=identity``) needs state vectors, not pixels."""
    _check_algo(cfg, "dbc")
    dbc, size = cfg.algo.dbc, cfg.env.image_size
    if dbc is not None and dbc.encoder == "identity":
        check(not cfg.env.pixels, "algo.dbc.encoder",
              f"identity passes state vectors to the actor and critic; env {cfg.env.name} has pixels=true "
              f"(use env.pixels=false, or algo.dbc.encoder=bisim or critic)")
    if cfg.env.pixels and dbc is not None:
        sizes = conv_sizes(size, [3] * dbc.num_layers, [2] + [1] * (dbc.num_layers - 1))
        check(min(sizes) >= 1, "env.image_size",
              f"{size}x{size} frames are too small for DBC's encoder (3x3 convs, stride 2 then 1, "
              f"algo.dbc.num_layers={dbc.num_layers}): spatial sizes {sizes}")


def _check_algo(cfg: RunnerConfig, algo: str) -> None:
    """A policy-training runner runs the algorithm of the same name (its hyperparameters section)."""
    check(cfg.algo.name == algo, "algo", f"runner={cfg.runner} needs algo={algo}, got algo.name={cfg.algo.name}")


def _check_no_algo(cfg: RunnerConfig) -> None:
    """A runner that learns no policy would leave an algo section unused: refused, not ignored."""
    check(cfg.algo.name == "none", "algo", f"runner={cfg.runner} learns no policy: needs algo=none, "
          f"got algo.name={cfg.algo.name}")


Check = Callable[[RunnerConfig], None]
# Runner name -> its checks, in plan order: the runner names ``Config.validate`` accepts.
RUNNER_CHECKS: dict[str, Check] = {
    "collect": validate_collect, "repr": validate_repr, "study": validate_study,
    "ppo": validate_ppo, "dbc": validate_dbc,
}
