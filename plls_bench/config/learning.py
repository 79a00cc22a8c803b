"""Schemas of policy learning and budgets (``algo/``, ``budget/``)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from omegaconf import MISSING

from plls_bench.config.checks import Validated, check, check_choice, check_fraction, check_nonnegative, check_positive

ALGO_NAMES = ("ppo", "dbc", "none")
BUDGET_NAMES = ("smoke", "quick", "paper")
FEATURE_EXTRACTORS = ("mlp", "paper_cnn", "separate_mlp")
PPO_ACTIVATIONS = ("tanh", "relu")  # train/networks.py builds these


# --------------------------------------------------------------------------- algorithms
@dataclass
class PPOConfig(Validated):
    """stable-baselines3 PPO settings (Tables 1 and 2 of the paper) and the shared policy/value net.

    The paper's networks share one trunk between policy and value (Sec. 5.1, 5.2). In SB3 that is a
    features extractor shared by actor and critic with linear heads: ``mlp`` is an MLP of
    ``policy_hidden`` on vector observations; ``paper_cnn`` is ``cnn_channels`` conv layers
    followed by ``cnn_hidden`` fully connected layers on (C, H, W) images. ``separate_mlp`` is SB3's
    own ``MlpPolicy`` (separate pi and vf MLPs of ``policy_hidden``), for recipes that are not the
    paper's, such as rl-baselines3-zoo's.

    Exploration and normalisation (the paper is silent on both) are off by default: ``use_sde``
    switches SB3's Gaussian to generalized state-dependent exploration (gSDE), whose noise matrix
    is resampled every ``sde_sample_freq`` steps (0: once per rollout, SB3's -1);
    ``normalize_obs`` / ``normalize_reward`` wrap the training env in SB3's ``VecNormalize``.
    """

    n_steps: int = MISSING
    learning_rate: float = MISSING
    n_epochs: int = MISSING
    batch_size: int = MISSING
    n_envs: int = MISSING
    gamma: float = MISSING
    gae_lambda: float = MISSING
    clip_range: float = MISSING
    vf_coef: float = MISSING
    ent_coef: float = MISSING
    max_grad_norm: float = 0.5
    features_extractor: str = "mlp"
    policy_hidden: list[int] = field(default_factory=lambda: [64, 64])
    activation: str = "tanh"
    cnn_channels: list[int] = field(default_factory=lambda: [32, 64, 128, 256])
    cnn_kernel_sizes: list[int] = field(default_factory=lambda: [4, 4, 4, 4])
    cnn_stride: int = 2
    cnn_hidden: list[int] = field(default_factory=lambda: [32, 32])
    log_std_init: float = 0.0
    ortho_init: bool = True
    use_sde: bool = False
    sde_sample_freq: int = 0
    normalize_obs: bool = False
    normalize_reward: bool = False
    vec_env: str = "dummy"
    eval_envs: int = 1

    @property
    def normalized(self) -> bool:
        """Whether the training env is wrapped in ``VecNormalize``."""
        return self.normalize_obs or self.normalize_reward

    @property
    def steps_per_iteration(self) -> int:
        """Agent steps of one PPO iteration (one rollout and update): ``n_envs * n_steps``."""
        return self.n_envs * self.n_steps

    def validate(self) -> None:
        for key in ("n_steps", "learning_rate", "n_epochs", "n_envs", "max_grad_norm", "cnn_stride",
                    "eval_envs"):
            check_positive(getattr(self, key), f"algo.ppo.{key}")
        check(isinstance(self.batch_size, int) and self.batch_size > 1, "algo.ppo.batch_size",
              f"must be an int > 1 (SB3 normalises advantages per minibatch), got {self.batch_size!r}")
        check(self.batch_size <= self.steps_per_iteration, "algo.ppo.batch_size",
              f"{self.batch_size} exceeds the rollout of algo.ppo.n_envs x algo.ppo.n_steps = "
              f"{self.steps_per_iteration}")
        check_fraction(self.gamma, "algo.ppo.gamma", open_right=False)
        check_fraction(self.gae_lambda, "algo.ppo.gae_lambda", open_right=False)
        check_positive(self.clip_range, "algo.ppo.clip_range")
        check_nonnegative(self.vf_coef, "algo.ppo.vf_coef")
        check_nonnegative(self.ent_coef, "algo.ppo.ent_coef")
        check_choice(self.features_extractor, FEATURE_EXTRACTORS, "algo.ppo.features_extractor")
        check_choice(self.activation, PPO_ACTIVATIONS, "algo.ppo.activation")
        check_choice(self.vec_env, ("dummy", "subproc"), "algo.ppo.vec_env")
        check(isinstance(self.sde_sample_freq, int) and self.sde_sample_freq >= 0, "algo.ppo.sde_sample_freq",
              f"must be an int >= 0 (0 = resample the gSDE noise once per rollout), got {self.sde_sample_freq!r}")
        check(self.use_sde or self.sde_sample_freq == 0, "algo.ppo.sde_sample_freq",
              f"{self.sde_sample_freq} has no effect without algo.ppo.use_sde=true")
        check(self.features_extractor != "separate_mlp" or len(self.policy_hidden) > 0, "algo.ppo.policy_hidden",
              "separate_mlp needs at least one hidden layer")
        check(len(self.cnn_kernel_sizes) == len(self.cnn_channels), "algo.ppo.cnn_kernel_sizes",
              "needs one kernel size per entry of algo.ppo.cnn_channels")
        for name in ("policy_hidden", "cnn_channels", "cnn_kernel_sizes", "cnn_hidden"):
            for i, width in enumerate(getattr(self, name)):
                check_positive(width, f"algo.ppo.{name}[{i}]")


TRANSITION_MODELS = ("deterministic", "probabilistic")
DBC_ENCODERS = ("bisim", "critic", "identity")


@dataclass
class DBCConfig(Validated):
    """Deep Bisimulation for Control (Zhang et al., ICLR 2021): SAC + bisimulation encoder.

    Values live in ``conf/algo/dbc.yaml`` with the reference flag each comes from
    (facebookresearch/deep_bisim4control, ``train.py`` and the ``run_*.sh`` launchers).
    ``encoder``: ``bisim`` (DBC), ``critic`` (pixel SAC: the same encoder trained by the critic
    alone; ``conf/algo/sac_pixel.yaml``) or ``identity`` (state SAC on the env's state vector, no
    representation losses; ``conf/algo/sac_state.yaml``). Its default keeps records made before
    the key existed loading, and it is left out of the config hash at that value.
    """

    encoder: str = "bisim"

    transition_model: str = MISSING
    hidden_dim: int = MISSING
    batch_size: int = MISSING
    discount: float = MISSING
    init_steps: int = MISSING
    replay_capacity: int = MISSING
    encoder_feature_dim: int = MISSING
    num_layers: int = MISSING
    num_filters: int = MISSING
    encoder_lr: float = MISSING
    encoder_tau: float = MISSING
    critic_lr: float = MISSING
    critic_beta: float = MISSING
    critic_tau: float = MISSING
    critic_target_update_freq: int = MISSING
    actor_lr: float = MISSING
    actor_beta: float = MISSING
    actor_log_std_min: float = MISSING
    actor_log_std_max: float = MISSING
    actor_update_freq: int = MISSING
    init_temperature: float = MISSING
    alpha_lr: float = MISSING
    alpha_beta: float = MISSING
    decoder_lr: float = MISSING
    decoder_weight_lambda: float = MISSING
    model_hidden_dim: int = MISSING
    sigma_min: float = MISSING
    sigma_max: float = MISSING
    bisim_coef: float = MISSING

    @property
    def steps_per_iteration(self) -> int:
        """Agent steps of one DBC iteration: one (act, update, env step); ``train/schedule.py``."""
        return 1

    def validate(self) -> None:
        check_choice(self.encoder, DBC_ENCODERS, "algo.dbc.encoder")
        check_choice(self.transition_model, TRANSITION_MODELS, "algo.dbc.transition_model")
        for key in ("hidden_dim", "batch_size", "replay_capacity", "encoder_feature_dim", "num_layers",
                    "num_filters", "encoder_lr", "critic_lr", "critic_target_update_freq", "actor_lr",
                    "actor_update_freq", "init_temperature", "alpha_lr", "decoder_lr",
                    "model_hidden_dim", "sigma_min"):
            check_positive(getattr(self, key), f"algo.dbc.{key}")
        for key in ("init_steps", "decoder_weight_lambda", "bisim_coef"):
            check_nonnegative(getattr(self, key), f"algo.dbc.{key}")
        check_fraction(self.discount, "algo.dbc.discount")
        for key in ("encoder_tau", "critic_tau"):
            check_fraction(getattr(self, key), f"algo.dbc.{key}", open_right=False)
        for key in ("critic_beta", "actor_beta", "alpha_beta"):
            value = getattr(self, key)
            check(0 <= value < 1, f"algo.dbc.{key}", f"must be in [0, 1), got {value!r}")
        check(self.actor_log_std_min < self.actor_log_std_max, "algo.dbc.actor_log_std_min",
              f"must be < algo.dbc.actor_log_std_max ({self.actor_log_std_max}), got {self.actor_log_std_min}")
        check(self.sigma_min < self.sigma_max, "algo.dbc.sigma_min",
              f"must be < algo.dbc.sigma_max ({self.sigma_max}), got {self.sigma_min}")


@dataclass
class AlgoConfig(Validated):
    name: str = "none"
    ppo: Optional[PPOConfig] = None
    dbc: Optional[DBCConfig] = None

    def validate(self) -> None:
        check_choice(self.name, ALGO_NAMES, "algo.name")
        if self.name != "none":
            check(getattr(self, self.name) is not None, f"algo.{self.name}",
                  f"algo.name={self.name} needs an algo.{self.name} section")


# --------------------------------------------------------------------------- budgets
@dataclass
class BudgetConfig(Validated):
    """How much compute a run gets; smoke/quick/paper profiles, specialised per task."""

    name: str = MISSING
    trials: int = MISSING
    data_episodes: int = MISSING
    data_steps_per_episode: int = MISSING
    repr_epochs: int = MISSING
    repr_action_epochs: Optional[int] = None  # V_a epochs when set; None: repr_epochs
    train_env_steps: int = MISSING
    eval_every_env_steps: int = MISSING
    eval_episodes: int = MISSING
    eval_max_steps: int = 0  # cap on a test episode's agent steps; 0 = the env's own time limit

    def validate(self) -> None:
        check_choice(self.name, BUDGET_NAMES, "budget.name")
        for key in ("trials", "data_episodes", "data_steps_per_episode", "repr_epochs",
                    "train_env_steps", "eval_every_env_steps", "eval_episodes"):
            check_positive(getattr(self, key), f"budget.{key}")
        check_nonnegative(self.eval_max_steps, "budget.eval_max_steps")
        if self.repr_action_epochs is not None:
            check_positive(self.repr_action_epochs, "budget.repr_action_epochs")

    def epochs_for(self, which: str) -> int:
        """Training epochs of V_s (``state``) or V_a (``action``). V_a may get its own count:
        an epoch of it costs about a thousandth of a V_s epoch on the same data."""
        if which == "action" and self.repr_action_epochs is not None:
            return self.repr_action_epochs
        return self.repr_epochs
