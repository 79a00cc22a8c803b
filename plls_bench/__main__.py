"""``python -m plls_bench +experiment=NAME [overrides]`` (``-m`` for multiruns).

The command line is composed and validated first, so a wrong value exits with one message naming
the key, before Hydra creates a run directory and before any compute. That includes a ``runs_dir``
this process cannot create or write, and asking for a device this machine lacks (``device=cuda``
without a GPU): config validation cannot check either, since it also runs when recorded configs
are read back on other machines.
"""
from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from plls_bench.config import ConfigError, to_config
from plls_bench.config.checks import check_writable_dir
from plls_bench.rundirs.composition import CONF_DIR, compose, expand_sweeps, register
from plls_bench.rundirs.devices import require_device

register()

_NO_VALIDATION_FLAGS = ("help", "hydra_help", "info", "shell_completion")
# Launchers whose jobs run on this machine; others (slurm) run them on nodes that may have the GPU
# the submitting machine lacks, so there each job checks its device when it starts (runner.execute).
_LOCAL_LAUNCHERS = ("basic", "parallel", "joblib", "submitit_local")


def validate_command_line(argv: list[str]) -> None:
    """Compose every job the command line describes; raise ConfigError on the first bad one."""
    from hydra._internal.utils import get_args_parser  # Hydra's own parser: same flags, same rules

    args = get_args_parser().parse_args(argv)
    if any(getattr(args, flag, False) for flag in _NO_VALIDATION_FLAGS) or args.config_dir:
        return
    jobs = expand_sweeps(args.overrides) if args.multirun else [args.overrides]
    here = not args.multirun or _launcher(args.overrides) in _LOCAL_LAUNCHERS
    for overrides in jobs:
        cfg = compose(overrides, config_name=args.config_name or "config")
        check_writable_dir(cfg.runs_dir, "runs_dir")  # Hydra creates run dirs under it right away
        if here:
            require_device(cfg.device)


def _launcher(overrides: list[str]) -> str:
    """The ``hydra/launcher`` choice of a command line (Hydra's default is ``basic``)."""
    chosen = [o.split("=", 1)[1] for o in overrides if o.lstrip("+~").startswith("hydra/launcher=")]
    return chosen[-1] if chosen else "basic"


@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
def hydra_main(dcfg: DictConfig) -> None:
    from plls_bench.pipeline.execute import execute

    execute(to_config(dcfg), Path(HydraConfig.get().runtime.output_dir))


def main() -> None:
    try:
        validate_command_line(sys.argv[1:])
    except ConfigError as err:
        print(f"plls_bench: invalid config: {err}", file=sys.stderr)
        sys.exit(2)
    hydra_main()


if __name__ == "__main__":
    main()
