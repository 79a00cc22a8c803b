"""Policy learning on stable-baselines3: the ``ppo`` runner, the paper's networks, checkpoints."""
