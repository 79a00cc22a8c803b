"""Run one composed config in its run directory: skip if done, resume (from its own checkpoint or
a partial record another session left, :mod:`plls_bench.rundirs.record_restore`) or start, record status.

Runners are looked up by ``cfg.runner`` in the registry (:mod:`plls_bench.pipeline.runner_registry`), whose
loaders import a runner's module only when it runs, so that choosing one task never imports
another's simulator.
"""
from __future__ import annotations

import logging
from pathlib import Path

from plls_bench.config import Config
from plls_bench.core.malloc_retain import retain_freed_memory
from plls_bench.core.seeding import derive_seeds, seed_everything
from plls_bench.core.signals import TERMINATED_EXIT_CODE, Terminated, sigterm_raises
from plls_bench.pipeline.runner_registry import runner_spec
from plls_bench.rundirs.devices import require_device
from plls_bench.rundirs.record_restore import seed_from_partial
from plls_bench.rundirs.run_dir import STATUS_DONE, STATUS_FAILED, STATUS_RUNNING, STATUS_STOPPED, Run, config_hash
from plls_bench.train.loop import TimeLimitReached

log = logging.getLogger(__name__)


def execute(cfg: Config, run_dir: str | Path) -> str:
    """Run ``cfg`` in ``run_dir``. Returns ``"skipped"`` (already done with this config) or
    ``"done"``, or ``"stopped"`` (at a checkpoint, by ``time_limit_min``: the next launch resumes it);
    raises after marking the run failed. SIGTERM marks the run stopped too, then exits with status
    143 (:func:`sigterm_raises`). A run dir holding a *different* config is
    moved aside under ``<runs_dir>/.superseded/`` first, never overwritten or deleted."""
    run, cfg_hash = Run(run_dir), config_hash(cfg)
    if run.is_done(cfg_hash):
        log.info("already done with config %s: %s", cfg_hash, run.path)
        return "skipped"
    require_device(cfg.device)  # a SLURM job's node may lack the GPU asked for: say so, touch nothing
    previous = run.identity()
    if previous is not None and previous != cfg_hash:
        moved = _supersede_keeping_hydra(run, cfg.runs_dir)
        log.warning("config changed (%s -> %s): previous run moved to %s", previous, cfg_hash, moved)
    seeded = seed_from_partial(run.path, cfg.runs_dir, cfg_hash)  # another session's unfinished trial
    if seeded is not None:
        log.info("resuming seed=%d from partial record %s at iteration %d", cfg.seed, *seeded)
    spec = runner_spec(cfg.runner)
    if cfg.time_limit_min > 0 and not spec.time_limited:
        log.info("runner %s runs to its end: time_limit_min applies to learners that checkpoint", cfg.runner)
    fn = spec.load()  # imports this runner's module (and simulator) only
    _configure_process(cfg)
    seed_everything(derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial).train)
    run.prepare(cfg, cfg_hash)
    run.write_status(STATUS_RUNNING, config_hash=cfg_hash)
    try:
        with sigterm_raises():
            fn(cfg, run)
    except TimeLimitReached as stop:
        log.info("%s", stop)
        run.write_status(STATUS_STOPPED, config_hash=cfg_hash, iteration=stop.at.iteration, reason=str(stop))
        return "stopped"
    except Terminated as stop:
        # the checkpoint files are written atomically, so the last complete one resumes the run
        log.warning("%s: the next launch resumes from the last checkpoint", stop)
        run.write_status(STATUS_STOPPED, config_hash=cfg_hash, reason=f"{stop}; resumes from the last checkpoint")
        raise SystemExit(TERMINATED_EXIT_CODE) from None
    except BaseException as err:
        run.write_status(STATUS_FAILED, config_hash=cfg_hash, error=f"{type(err).__name__}: {err}")
        raise
    run.write_status(STATUS_DONE, config_hash=cfg_hash)
    return "done"


def _supersede_keeping_hydra(run: Run, runs_dir: str) -> Path:
    """Move the old run aside, but keep Hydra's files of *this* launch (already written)."""
    import shutil
    import tempfile

    keep = [p for p in (run.path / ".hydra", run.path / "run.log") if p.exists()]
    with tempfile.TemporaryDirectory(dir=run.path.parent) as hold:
        for path in keep:
            shutil.move(str(path), str(Path(hold) / path.name))
        moved = run.supersede(runs_dir)
        run.path.mkdir(parents=True, exist_ok=True)
        for path in keep:
            shutil.move(str(Path(hold) / path.name), str(run.path / path.name))
    return moved


def _configure_process(cfg: Config) -> None:
    """Process-wide speed settings, none of which changes what the run computes."""
    if cfg.retain_freed_memory:
        retain_freed_memory()
    if cfg.torch_threads > 0:
        import torch

        torch.set_num_threads(cfg.torch_threads)
