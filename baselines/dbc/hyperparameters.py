"""What the DBC agent reads of its settings, as a Protocol.

The agent depends on no config schema: the suite's ``plls_bench.config.DBCConfig`` (values and
their sources in ``conf/algo/dbc.yaml``) satisfies this by its fields, and so does any object with
these attributes. ``baselines`` sits below the suite's learners, which import it.
"""
from __future__ import annotations

from typing import Protocol


class Hyperparameters(Protocol):
    """DBC's hyperparameters, named as the reference's flags."""

    encoder: str                 # bisim: DBC's learned encoder; identity: state SAC, no representation
    transition_model: str        # probabilistic | deterministic
    hidden_dim: int
    discount: float
    encoder_feature_dim: int
    num_layers: int
    num_filters: int
    encoder_lr: float
    encoder_tau: float
    critic_lr: float
    critic_beta: float
    critic_tau: float
    critic_target_update_freq: int
    actor_lr: float
    actor_beta: float
    actor_log_std_min: float
    actor_log_std_max: float
    actor_update_freq: int
    init_temperature: float
    alpha_lr: float
    alpha_beta: float
    decoder_lr: float
    decoder_weight_lambda: float
    model_hidden_dim: int
    sigma_min: float
    sigma_max: float
    bisim_coef: float
