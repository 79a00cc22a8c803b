"""Deep Bisimulation for Control (Zhang et al., ICLR 2021), written from the paper and the
authors' reference code (facebookresearch/deep_bisim4control), plus an exact bisimulation-metric
oracle for small finite MDPs (:mod:`baselines.dbc.oracle`, used by the tests).

Modules: ``hyperparameters`` (what the agent reads of its settings: a Protocol, so that no config
schema of the suite is imported here), ``encoder`` (conv/MLP trunk -> Linear -> LayerNorm),
``models`` (actor, twin critic, transition model, reward decoder), ``bisim`` (the representation
losses), ``agent`` (updates and checkpoint state), ``replay`` (frames stored once, stacks rebuilt on
sampling), ``oracle``. It imports nothing of the suite: the suite hands the pixel encoder its conv
stack (``DBCAgent(..., conv_stack=...)``, :func:`plls_bench.repr.pixel_trunk.conv_stack`).
"""
from baselines.dbc.agent import Batch, DBCAgent
from baselines.dbc.replay import FrameReplay

__all__ = ["Batch", "DBCAgent", "FrameReplay"]
