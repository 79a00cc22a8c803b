"""The runner registry: what each ``runner=NAME`` is, as typed :class:`RunnerSpec` entries.

Everything that depends on which runner a config names asks here (the plan's order and costs,
filmstrips, ``reproduce``) instead of comparing names. Config validation is the one exception: the
config layer sits below this module, so its runner checks are its own table
(:data:`plls_bench.config.runner_checks.RUNNER_CHECKS`), with the same names as :data:`SPECS`.

The registry sits above everything it loads (tests/test_imports.py): nothing it loads imports it
back. It stays light: run functions and policy loaders are reached through small loaders whose
plain ``import`` runs only when called, so choosing one task never imports another task's
simulator (or torch).

Adding a runner is one module with a ``run(cfg, run)`` function, one entry in :data:`SPECS` and its
config checks (docs/architecture.md, "Adding a runner").
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal, get_args

from plls_bench.rundirs.record_snapshot import ResumeFiles  # run dir -> its last checkpoint's files and iteration

if TYPE_CHECKING:  # types only: the config root and the run dir must not be imported at load time
    from plls_bench.config import Config
    from plls_bench.core.metric_rows import Lookup
    from plls_bench.rundirs.run_dir import Run
    from plls_bench.train.trained_policy import PolicyLoader

RunFn = Callable[["Config", "Run"], None]
# What a committed record carries of a run (``pipeline/record_export.py``):
PolicyFiles = Callable[[Path], "dict[str, Path | bytes]"]  # run dir -> the files that rebuild its last policy
CheckpointsAt = Literal["iteration", "episode"]  # when a time-limited runner checkpoints


@dataclass(frozen=True)
class RunnerSpec:
    """One runner: how to load it, where it sits in a plan, what it costs, whether it films."""

    name: str
    load: Callable[[], RunFn]                  # imports the runner's module when called
    # Plan stage: artifacts before the runners that read them. Runners that read nothing of each
    # other share a stage, so one launch queue keeps every core busy with all their trials.
    order: int
    # How ``bench/throughput.py`` times its rates for the dry run: the name of one of its
    # measurements (MEASURES), which gives the rate keys of its kinds (``rates.rate_keys``).
    measure: str
    trains_policy: bool = False                # costed as train + eval env steps (rate kinds train, eval)
    uses_dataset: bool = False                 # reads (building if missing) the task's stored dataset
    costs_per_run: bool = False                # a fixed cost per run (rate kind run: ``<name>/<experiment>``)
    load_policy: Callable[[], PolicyLoader] | None = None  # imports its policy loader; None: nothing to film
    # What one ``iteration`` of its metric rows is, for the curves' x axis: ``{}`` filled from the
    # recorded config's ``iteration_keys``. How many env steps it is: ``train/schedule.py``.
    iteration_unit: str = "iteration"
    iteration_keys: tuple[str, ...] = ()
    # What its committed records carry: its policy's files (``load_policy_files``; None: none), and
    # for an unfinished run the checkpoint that resumes it (``load_resume_files``; None: unfinished
    # runs are not carried, ``not_carried`` says why). The same files resume a run from its own run
    # dir (plan._resume_point), so a runner that is never carried may still list them.
    load_policy_files: Callable[[], PolicyFiles] | None = None
    load_resume_files: Callable[[], ResumeFiles] | None = None
    not_carried: str = "no checkpoint to carry"
    # Its checkpoint holds a replay buffer (and the optimisers of several networks): a stopped run
    # is never carried as a partial record, whatever its size, since a record of it would grow with
    # every sitting that every clone downloads. It resumes from its run dir on the machine that ran
    # it; the export writes its metrics so far as a pending record (pipeline/record_export.py).
    snapshot_holds_replay: bool = False
    # Trains in the skeleton of ``train/loop.py``, so ``time_limit_min`` stops it at a checkpoint;
    # the other runners run to their end (a launch with a deadline starts one only with time for it).
    time_limited: bool = False
    # When a time-limited runner checkpoints: every iteration, or at the end of each episode of its
    # one env and at each evaluation; the launch starts none that cannot reach its first checkpoint
    # before the deadline (launch.start_minutes).
    checkpoints_at: CheckpointsAt = "iteration"
    # A one-off run of extra learning in one iteration, as (iteration, how many iterations' worth):
    # DBC's burst of init_steps updates. The launch counts it in a first interval that holds it
    # (plan._burst_share); the trainer foretells it to its time limit (train/loop.py).
    burst: Callable[[Config], tuple[int, int]] | None = None

    def __post_init__(self) -> None:
        if self.checkpoints_at not in get_args(CheckpointsAt):
            raise ValueError(f"runner {self.name!r}: checkpoints_at={self.checkpoints_at!r} is not one "
                             f"of {', '.join(get_args(CheckpointsAt))}")

    @property
    def films(self) -> bool:
        return self.load_policy is not None

    def iteration_label(self, cfg: Lookup) -> str:
        """The x-axis label of one iteration of a run of this runner (``cfg``: its recorded config)."""
        return self.iteration_unit.format(*(cfg(key, None) for key in self.iteration_keys))


# --------------------------------------------------------------------------- loaders
def _collect() -> RunFn:
    from plls_bench.data import run
    return run


def _repr() -> RunFn:
    from plls_bench.repr.build_run import run
    return run


def _study() -> RunFn:
    from plls_bench.studies.latent_space import run
    return run


def _ppo() -> RunFn:
    from plls_bench.train.ppo import run
    return run


def _dbc() -> RunFn:
    from plls_bench.train.dbc import run
    return run


def _ppo_policy() -> PolicyLoader:
    from plls_bench.train.ppo_model import trained_policy
    return trained_policy


def _dbc_policy() -> PolicyLoader:
    from plls_bench.train.dbc import trained_policy
    return trained_policy


def _ppo_checkpoint() -> ResumeFiles:
    from plls_bench.train.checkpoint import committed_files
    return committed_files


def _dbc_checkpoint() -> ResumeFiles:
    from plls_bench.train.dbc_state import committed_files
    return committed_files


def _dbc_burst(cfg: Config) -> tuple[int, int]:
    """The reference's init_steps updates at once, in the iteration of agent step init_steps."""
    assert cfg.algo.dbc is not None
    return cfg.algo.dbc.init_steps, cfg.algo.dbc.init_steps


def _ppo_policy_files() -> PolicyFiles:
    from plls_bench.train.checkpoint import policy_files
    return policy_files


def _dbc_policy_files() -> PolicyFiles:
    from plls_bench.train.dbc_state import policy_files
    return policy_files


# --------------------------------------------------------------------------- the registry
SPECS: tuple[RunnerSpec, ...] = (
    RunnerSpec("collect", _collect, order=0, measure="collection", uses_dataset=True),
    RunnerSpec("repr", _repr, order=1, measure="vae_epoch", uses_dataset=True),
    RunnerSpec("study", _study, order=2, measure="study_run", uses_dataset=True, costs_per_run=True),
    # one PPO iteration: a rollout of n_envs x n_steps vector-env steps and its update
    RunnerSpec("ppo", _ppo, order=3, measure="ppo_iterations", trains_policy=True, load_policy=_ppo_policy,
               iteration_unit="PPO iteration ({} envs x {} steps)",
               iteration_keys=("algo.ppo.n_envs", "algo.ppo.n_steps"),
               load_policy_files=_ppo_policy_files, load_resume_files=_ppo_checkpoint, time_limited=True),
    # one DBC iteration: one agent step (action repeat frames) and its update
    RunnerSpec("dbc", _dbc, order=3, measure="dbc_steps", trains_policy=True, load_policy=_dbc_policy,
               iteration_unit="iteration (agent steps)", load_policy_files=_dbc_policy_files,
               # resumes from its own run dir only: agent, optimisers and frame replay stay there
               load_resume_files=_dbc_checkpoint, snapshot_holds_replay=True, time_limited=True,
               checkpoints_at="episode", burst=_dbc_burst),
)
RUNNERS: dict[str, RunnerSpec] = {spec.name: spec for spec in SPECS}


def runner_names() -> tuple[str, ...]:
    return tuple(RUNNERS)


def runner_spec(name: str) -> RunnerSpec:
    """The spec of ``name``; KeyError listing the registered runners otherwise."""
    if name not in RUNNERS:
        raise KeyError(f"runner {name!r} is not implemented; available: {', '.join(RUNNERS)}")
    return RUNNERS[name]


def filming_runners() -> tuple[str, ...]:
    """Runners whose runs hold a policy a filmstrip can show."""
    return tuple(spec.name for spec in SPECS if spec.films)


def iteration_label(cfg: Lookup) -> str:
    """The x-axis label of a recorded run's ``iteration``: its runner's, plain for an unknown runner."""
    spec = RUNNERS.get(cfg("runner", None))
    return spec.iteration_label(cfg) if spec else "iteration"
