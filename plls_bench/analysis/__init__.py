"""Analyses of trained models: the MountainCar latent-space studies (Figs 7-9, runner ``study``)
and policy filmstrips (Figs 11, 19, 22, filmed by ``python -m plls_bench.film RUN_DIR``)."""
