"""``python -m plls_bench +experiment=NAME [overrides]`` (``-m`` for multiruns).

The command line is composed and validated first, so a wrong value exits with one message naming
the key, before Hydra creates a run directory and before any compute.
"""
from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from plls_bench.composition import CONF_DIR, compose, expand_sweeps, register
from plls_bench.config import ConfigError, to_config

register()

_NO_VALIDATION_FLAGS = ("help", "hydra_help", "info", "shell_completion")


def validate_command_line(argv: list[str]) -> None:
    """Compose every job the command line describes; raise ConfigError on the first bad one."""
    from hydra._internal.utils import get_args_parser  # Hydra's own parser: same flags, same rules

    args = get_args_parser().parse_args(argv)
    if any(getattr(args, flag, False) for flag in _NO_VALIDATION_FLAGS) or args.config_dir:
        return
    jobs = expand_sweeps(args.overrides) if args.multirun else [args.overrides]
    for overrides in jobs:
        compose(overrides, config_name=args.config_name or "config")


@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
def hydra_main(dcfg: DictConfig) -> None:
    from plls_bench.runner import execute

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
