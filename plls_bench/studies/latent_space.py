"""Runner ``study``: MountainCar's latent-space studies of a trained V_a (Figs 7, 8, 9; Sec. 5.1).

Every study samples actions (``study.action_ranges``), encodes them with V_a to (mu, std), draws
``study.samples_per_action`` latents e = mu + std * eps each, decodes ``study.decode`` (e, or mu)
to reconstructed actions a_hat (clipped to the action box, as PL-LS's action path does), and
drives the car with raw and reconstructed actions from ``study.s0``: in sequence (``multistep``)
or one step each (``onestep``, ``generalisation``). It writes docs/architecture.md's
``studies/<name>.npz`` arrays and ``metrics/study.json``, whose numbers (see :func:`structure`,
:func:`reconstruction`, :func:`dynamics`) make the paper's claims checkable.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from plls_bench.config import Config, StudyConfig
from plls_bench.core.atomic_files import read_json
from plls_bench.core.seeding import derive_seeds
from plls_bench.repr.models import ActionVAE
from plls_bench.repr.store import ensure_representations
from plls_bench.rundirs.artifacts import npz_bytes
from plls_bench.rundirs.run_dir import Run
from plls_bench.studies import measures
from plls_bench.studies.mountaincar import MountainCar

log = logging.getLogger(__name__)

Metrics = dict[str, float]


@dataclass(frozen=True)
class Encoded:
    """Actions through V_a. K actions, S samples each, D latent dims."""

    actions: np.ndarray  # (K,) raw actions, in ``action_ranges`` order
    mu: np.ndarray       # (K, D) posterior means
    std: np.ndarray      # (K, D) posterior standard deviations
    e: np.ndarray        # (K, S, D) samples mu + std * eps
    decoded: np.ndarray  # (K, S) reconstructed actions, clipped to the action box
    decoded_mu: np.ndarray  # (K,) decode(mu), clipped: the noise-free reconstruction, for reference


def sample_actions(study: StudyConfig, rng: np.random.Generator) -> np.ndarray:
    """``(K,)`` actions, ``actions_per_range`` uniform in each range in turn; the end nearer to
    zero is open (``[-1, 0]`` -> [-1, 0), ``[0, 1]`` -> (0, 1]; Sec. 5.1)."""
    parts = []
    for low, high in study.action_ranges:
        u = rng.random(study.actions_per_range)  # [0, 1)
        parts.append(high - (high - low) * u if abs(high) > abs(low) else low + (high - low) * u)
    return np.concatenate(parts)


def encode(vae: ActionVAE, actions: np.ndarray, samples: int, rng: np.random.Generator,
           decode: str, bounds: tuple[float, float]) -> Encoded:
    """Encode ``actions`` ``(K,)``, draw ``samples`` e each (eps from ``rng``) and decode e, or mu
    when ``decode == "mu"`` (then every sample of an action decodes alike)."""
    device = next(vae.parameters()).device
    with torch.inference_mode():
        mu_t, std_t = vae.encode(torch.as_tensor(actions[:, None], dtype=torch.float32, device=device))
        mu, std = mu_t.cpu().double().numpy(), std_t.cpu().double().numpy()
        eps = rng.standard_normal((len(actions), samples, mu.shape[1]))
        e = mu[:, None, :] + std[:, None, :] * eps
        source = e if decode == "e" else np.broadcast_to(mu[:, None, :], e.shape)

        def dec(z: np.ndarray) -> np.ndarray:
            out = vae.decode(torch.as_tensor(z.reshape(-1, z.shape[-1]), dtype=torch.float32, device=device))
            return np.clip(out.cpu().double().numpy()[:, 0], *bounds).reshape(z.shape[:-1])

        return Encoded(actions, mu, std, e, dec(source), dec(mu))


# --------------------------------------------------------------------------- the three studies
def multistep(enc: Encoded, car: MountainCar, study: StudyConfig, shuffle: np.ndarray) -> tuple[dict, Metrics]:
    """Fig 7: raw and reconstructed actions applied in sequence from s0 (two trajectories)."""
    s0, decoded = np.asarray(study.s0, dtype=np.float64), enc.decoded[:, 0]
    raw_states, decoded_states = car.trajectory(s0, enc.actions), car.trajectory(s0, decoded)
    shuffled_states = car.trajectory(s0, enc.actions[shuffle])
    arrays = {"actions": enc.actions, "mu": enc.mu, "e": enc.e[:, 0], "decoded": decoded,
              "states_raw": raw_states, "states_decoded": decoded_states}
    metrics = dynamics(raw_states, decoded_states, shuffled_states, car.state_range)
    for suffix, states in (("", decoded_states), ("_shuffled", shuffled_states)):
        metrics[f"dynamics/tracking_steps{suffix}"] = tracking_steps(raw_states, states, car.state_range,
                                                                     study.tracking_tolerance)
    return arrays, metrics


def onestep(enc: Encoded, car: MountainCar, study: StudyConfig, shuffle: np.ndarray) -> tuple[dict, Metrics]:
    """Fig 8: each raw and each reconstructed action applied once from s0."""
    s0, decoded = np.asarray(study.s0, dtype=np.float64), enc.decoded[:, 0]
    raw_next, decoded_next = car.one_step(s0, enc.actions), car.one_step(s0, decoded)
    metrics = dynamics(raw_next, decoded_next, car.one_step(s0, enc.actions[shuffle]), car.state_range)
    metrics["dynamics/direction_agreement"] = direction_agreement(s0, raw_next, decoded_next)
    arrays = {"actions": enc.actions, "mu": enc.mu, "e": enc.e[:, 0], "decoded": decoded,
              "next_states_raw": raw_next, "next_states_decoded": decoded_next, "s0": s0}
    return arrays, metrics


def generalisation(enc: Encoded, car: MountainCar, study: StudyConfig, shuffle: np.ndarray) -> tuple[dict, Metrics]:
    """Fig 9: each action's S reconstructions (one per sample e) applied once from s0. Also
    stores ``next_states_raw`` ``(K, 2)``, the raw actions' next states."""
    s0 = np.asarray(study.s0, dtype=np.float64)
    raw_next, decoded_next = car.one_step(s0, enc.actions), car.one_step(s0, enc.decoded)
    samples = enc.decoded.shape[1]
    raw_each = np.repeat(raw_next[:, None], samples, axis=1)  # (K, S, 2): the raw outcome per sample
    shuffled = car.one_step(s0, enc.actions[shuffle])
    metrics = dynamics(raw_each, decoded_next, np.repeat(shuffled[:, None], samples, axis=1), car.state_range)
    metrics["dynamics/direction_agreement"] = direction_agreement(s0, raw_each, decoded_next)
    metrics["dynamics/mean_next_velocity_spread"] = float(decoded_next[..., 1].std(axis=1).mean())
    metrics["recon/mean_within_action_std"] = float(enc.decoded.std(axis=1).mean())
    arrays = {"actions": enc.actions, "mu": enc.mu, "std": enc.std, "e": enc.e, "decoded": enc.decoded,
              "next_states": decoded_next, "next_states_raw": raw_next, "s0": s0}
    return arrays, metrics


# (encoded actions, car, settings, shuffling permutation of the actions) -> (arrays, metrics)
STUDIES: dict[str, Callable[[Encoded, MountainCar, StudyConfig, np.ndarray], tuple[dict, Metrics]]] = {
    "multistep": multistep, "onestep": onestep, "generalisation": generalisation}


# --------------------------------------------------------------------------- the numbers
def structure(enc: Encoded, knn: int) -> Metrics:
    """Does the latent space keep the action space's structure?

    - ``structure/spearman_action_latent_distance``: Spearman correlation of pairwise action
      distances with pairwise distances of the sampled e (what Figs 7-9 plot; every sample
      against its action), ``..._mu_distance`` the same with the posterior means mu;
    - ``structure/knn_overlap_mu``: share of each action's ``knn`` nearest actions that are among
      its mu's ``knn`` nearest mus (chance: knn / (K - 1));
    - ``structure/left_right_separability``: share of the e on their side of a linear SVM
      fitted to tell left (a < 0) from right (a > 0) actions (1.0 = two linearly separable
      clusters, about 0.5 = fully mixed); ``..._mu``: the same for mu.
    """
    samples = enc.e.shape[1]
    actions_each, e_flat = np.repeat(enc.actions, samples), enc.e.reshape(-1, enc.e.shape[-1])
    left = enc.actions < 0
    return {
        "structure/spearman_action_latent_distance": measures.distance_rank_correlation(actions_each, e_flat),
        "structure/spearman_action_mu_distance": measures.distance_rank_correlation(enc.actions, enc.mu),
        "structure/knn_overlap_mu": measures.knn_overlap(enc.actions, enc.mu, knn),
        "structure/knn_chance": knn / (len(enc.actions) - 1),
        "structure/left_right_separability": measures.linear_separability(e_flat, np.repeat(left, samples)),
        "structure/left_right_separability_mu": measures.linear_separability(enc.mu, left),
    }


def reconstruction(enc: Encoded) -> Metrics:
    """How far decoded actions are from the raw ones (:func:`measures.deviation_stats` on every
    decoded a_hat, as ``recon/<key>``), and ``recon/mean_abs_action_error_mu`` for decode(mu)."""
    metrics = {f"recon/{k}": v for k, v in measures.deviation_stats(enc.actions, enc.decoded).items()}
    metrics["recon/mean_abs_action_error_mu"] = float(np.abs(enc.decoded_mu - enc.actions).mean())
    return metrics


def dynamics(raw: np.ndarray, decoded: np.ndarray, shuffled: np.ndarray, scale: np.ndarray) -> Metrics:
    """Do reconstructed actions move the car like the raw ones? States ``(..., 2)`` reached
    with raw, reconstructed and, as a no-structure reference, randomly permuted raw actions.

    - ``dynamics/mean_state_error``: mean distance of decoded-action states to raw-action states,
      x and x_dot each divided by its span (:func:`measures.state_error`);
    - ``dynamics/mean_state_error_shuffled``: the same for the permuted actions (same action
      distribution, no correspondence), and ``dynamics/state_error_vs_shuffled`` the ratio
      (0: identical effect; about 1: no better than an unrelated action);
    - ``dynamics/mean_position_error``, ``dynamics/mean_velocity_error``: mean |difference| of
      x and of x_dot, in the env's units.
    """
    error, baseline = measures.state_error(decoded, raw, scale), measures.state_error(shuffled, raw, scale)
    diff = np.abs(np.asarray(decoded) - np.asarray(raw))
    return {"dynamics/mean_state_error": error, "dynamics/mean_state_error_shuffled": baseline,
            "dynamics/state_error_vs_shuffled": error / baseline if baseline > 0 else float("nan"),
            "dynamics/mean_position_error": float(diff[..., 0].mean()),
            "dynamics/mean_velocity_error": float(diff[..., 1].mean())}


def tracking_steps(raw: np.ndarray, other: np.ndarray, scale: np.ndarray, tolerance: float) -> int:
    """``dynamics/tracking_steps`` (``..._shuffled`` for permuted actions): steps until the
    trajectory ``other`` ``(N + 1, 2)`` is first more than ``tolerance`` (in span-scaled state
    units, as ``dynamics/mean_state_error``) away from ``raw``; N when it never is."""
    apart = np.linalg.norm((other - raw) / scale, axis=-1) > tolerance
    return int(np.argmax(apart)) if apart.any() else len(raw) - 1


def direction_agreement(s0: np.ndarray, raw_next: np.ndarray, decoded_next: np.ndarray) -> float:
    """``dynamics/direction_agreement``: share of reconstructed actions that change the velocity
    in the same direction as their raw action does, one step from ``s0``."""
    return float(np.mean(np.sign(raw_next[..., 1] - s0[1]) == np.sign(decoded_next[..., 1] - s0[1])))


# --------------------------------------------------------------------------- the runner
def study_rngs(cfg: Config) -> tuple[np.random.Generator, ...]:
    """Independent generators for the actions, the eps of e and the shuffled reference, from the
    trial's training stream: changing one count never changes the other draws."""
    seed = derive_seeds(cfg.seed, cfg.data_seed, cfg.repr.per_trial).train
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))


def run(cfg: Config, run: Run) -> None:
    """Runner ``study``: the study ``cfg.study`` against the V_a of ``cfg`` (built if missing)."""
    study = cfg.study
    assert study is not None, "Config.validate requires a study section for runner=study"
    reprs = ensure_representations(cfg)
    vae, artifact = reprs.action_vae, reprs.artifacts["action"].path
    assert vae is not None, "Config.validate requires repr/action=vae for runner=study"
    actions_rng, eps_rng, shuffle_rng = study_rngs(cfg)
    with MountainCar(cfg.env) as car:
        enc = encode(vae, sample_actions(study, actions_rng), study.samples_per_action, eps_rng,
                     study.decode, (car.action_low, car.action_high))
        arrays, metrics = STUDIES[study.name](enc, car, study, shuffle_rng.permutation(len(enc.actions)))
    metrics = {**structure(enc, study.knn), **reconstruction(enc), **metrics}
    run.write_bytes(f"studies/{study.name}.npz", npz_bytes(arrays))
    run.write_json("metrics/study.json", {**metrics, **_va_identity(artifact)})
    log.info("%s study: %s", study.name, ", ".join(f"{k} {v:.4g}" for k, v in sorted(metrics.items())))


def _va_identity(artifact: Path) -> dict[str, object]:
    """Which V_a the study probed: its artifact key, latent size and test MSE."""
    test, meta = read_json(artifact / "test.json") or {}, read_json(artifact / "meta.json") or {}
    return {"va_artifact": artifact.name, "va_latent_dim": meta.get("latent_dim"), "va_test_mse": test.get("test_mse")}
