"""Policy learning: the ``ppo`` runner on stable-baselines3 (the paper's networks, checkpoints) and the
``dbc`` runner."""
