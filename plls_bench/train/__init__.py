"""Policy-learning runners (PPO, DBC)."""
