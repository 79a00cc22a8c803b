"""The PL-LS vector-env wrappers: spaces, one batched forward per vector step, exact plumbing."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from plls_bench.envs import make_vec_env
from plls_bench.repr.accounting import parameter_counts
from plls_bench.repr.latent_wrappers import LatentAction, LatentObservation, latent_modules, wrap_latent
from plls_bench.repr.pixel_trunk import pixels_to_unit
from plls_bench.repr.store import ensure_representations
from plls_bench.repr.train import new_model
from tests.conftest import compose_preset


class Recorder(VecEnvWrapper):
    """Keeps what the inner envs returned and received, to check the wrappers against."""

    def __init__(self, venv: VecEnv) -> None:
        super().__init__(venv)
        self.obs: np.ndarray | None = None
        self.infos: list[dict] = []
        self.actions: np.ndarray | None = None

    def reset(self):
        self.obs = self.venv.reset()
        return self.obs

    def step_async(self, actions: np.ndarray) -> None:
        self.actions = np.array(actions)
        self.venv.step_async(actions)

    def step_wait(self):
        self.obs, rewards, dones, infos = self.venv.step_wait()
        self.infos = [{k: np.array(v) if isinstance(v, np.ndarray) else v for k, v in i.items()} for i in infos]
        return self.obs, rewards, dones, infos


def count_calls(monkeypatch, obj: object, name: str) -> list[int]:
    """Patch ``obj.name`` to record the batch size of every call."""
    calls: list[int] = []
    real = getattr(obj, name)

    def counted(x: torch.Tensor):
        calls.append(len(x))
        return real(x)

    monkeypatch.setattr(obj, name, counted)
    return calls


def check_vec_step(venv: VecEnv, obs, rewards, dones, infos) -> None:
    """What SB3 learners rely on: batched arrays of the declared spaces' shapes and dtypes."""
    n = venv.num_envs
    assert obs.shape == (n, *venv.observation_space.shape) and obs.dtype == venv.observation_space.dtype
    assert all(venv.observation_space.contains(o) for o in obs)
    assert rewards.shape == (n,) and np.issubdtype(rewards.dtype, np.floating)
    assert dones.shape == (n,) and dones.dtype == bool
    assert len(infos) == n and all(isinstance(i, dict) for i in infos)


def test_no_representation_leaves_the_env_untouched(runs_dir: Path) -> None:
    cfg = compose_preset(None, runs_dir)
    venv = make_vec_env(cfg.env, 2, seed=0)
    assert wrap_latent(venv, ensure_representations(cfg)) is venv
    assert not any(runs_dir.glob("**/*")), "nothing trained or written"
    venv.close()


@pytest.mark.parametrize("n_envs", [1, 4])
def test_latent_action_decodes_all_envs_in_one_pass(n_envs: int, runs_dir: Path, monkeypatch) -> None:
    cfg = compose_preset(None, runs_dir, "repr/action=vae")
    vae = new_model(cfg, "action").eval().requires_grad_(False)
    recorder = Recorder(make_vec_env(cfg.env, n_envs, seed=0))
    venv = LatentAction(recorder, vae, bound=3.0)
    assert venv.action_space.shape == (3,) and venv.action_space.dtype == np.float32
    assert np.all(venv.action_space.low == -3.0) and np.all(venv.action_space.high == 3.0)
    calls = count_calls(monkeypatch, vae, "decode")
    rng = np.random.default_rng(0)
    obs = venv.reset()
    for step in range(1, 21):
        e = rng.uniform(-6, 6, size=(n_envs, 3)).astype(np.float32)  # half of them beyond the bound
        check_vec_step(venv, *venv.step(e))
        assert calls == [n_envs] * step, "exactly one decoder forward per vector step"
        with torch.no_grad():
            expected = vae.decoder(torch.as_tensor(np.clip(e, -3, 3))).numpy()
        assert np.allclose(recorder.actions, np.clip(expected, -1, 1), atol=1e-6)
        assert np.array_equal(venv.last_env_actions, recorder.actions)
    assert obs.shape == (n_envs, 2)  # MountainCar's raw state: no V_s
    venv.close()


def test_latent_observation_encodes_steps_and_terminal_observations_in_one_pass(runs_dir: Path, monkeypatch) -> None:
    n_envs = 3
    cfg = compose_preset(None, runs_dir, "env=carracing", "repr/state=vae", "env.max_episode_steps=3")
    vae = new_model(cfg, "state").eval().requires_grad_(False)
    recorder = Recorder(make_vec_env(cfg.env, n_envs, seed=0))
    venv = LatentObservation(recorder, vae)
    assert venv.observation_space.shape == (32,) and venv.observation_space.dtype == np.float32
    calls = count_calls(monkeypatch, vae, "encode")
    obs = venv.reset()
    assert calls == [n_envs] and obs.shape == (n_envs, 32) and obs.dtype == np.float32
    terminal_seen = 0
    for step in range(1, 8):
        actions = np.stack([venv.action_space.sample() for _ in range(n_envs)])
        obs, rewards, dones, infos = venv.step(actions)
        check_vec_step(venv, obs, rewards, dones, infos)
        finished = [i for i, info in enumerate(recorder.infos) if "terminal_observation" in info]
        assert len(calls) == 1 + step, "exactly one encoder forward per vector step"
        assert calls[-1] == n_envs + len(finished), "terminal observations ride in the same pass"
        raw = np.concatenate([recorder.obs, *(recorder.infos[i]["terminal_observation"][None] for i in finished)])
        with torch.no_grad():
            mu = vae.encoder(pixels_to_unit(torch.as_tensor(raw)))[0].numpy()  # uint8 frames, as V_s trains
        assert np.allclose(obs, mu[:n_envs], atol=1e-5)
        for row, i in enumerate(finished, start=n_envs):
            assert infos[i]["terminal_observation"].shape == (32,)
            assert np.allclose(infos[i]["terminal_observation"], mu[row], atol=1e-5)
        terminal_seen += len(finished)
    assert terminal_seen >= n_envs, "episodes of 3 steps must have ended within 7 steps"
    venv.close()


def test_wrappers_refuse_envs_their_vae_does_not_fit(runs_dir: Path) -> None:
    cfg = compose_preset(None, runs_dir, "env=carracing", "repr/state=vae")
    venv = make_vec_env(compose_preset(None, runs_dir).env, 1, seed=0)  # MountainCar
    with pytest.raises(ValueError, match=r"LatentObservation needs Box observations of shape \(3, 96, 96\)"):
        LatentObservation(venv, new_model(cfg, "state"))
    with pytest.raises(ValueError, match=r"LatentAction needs a Box action space of shape \(3,\)"):
        LatentAction(venv, new_model(cfg, "action", 3), bound=3.0)
    venv.close()


@pytest.mark.slow
def test_pl_ls_carracing_env_with_trained_vs_and_va(runs_dir: Path) -> None:
    """The full PL-LS env at smoke budget: z in R^32 in, e in [-3, 3]^32 out, raw actions valid."""
    cfg = compose_preset(None, runs_dir, "env=carracing", "repr/state=vae", "repr/action=vae")
    recorder = Recorder(make_vec_env(cfg.env, 2, seed=0))
    venv = wrap_latent(recorder, ensure_representations(cfg))
    assert venv.observation_space.shape == (32,) and venv.action_space.shape == (32,)
    assert set(latent_modules(venv)) == {"V_s.encoder", "V_a.decoder"}
    counts = parameter_counts(latent_modules(venv), trainable=[])
    assert counts["total"] > 0 and counts["trainable"] == 0
    venv.reset()
    venv.action_space.seed(0)
    for _ in range(5):
        check_vec_step(venv, *venv.step(np.stack([venv.action_space.sample() for _ in range(2)])))
        inner = recorder.venv.action_space
        assert np.all(recorder.actions >= inner.low) and np.all(recorder.actions <= inner.high)
    venv.close()


@pytest.mark.slow
def test_sb3_ppo_trains_through_the_latent_action_wrapper(runs_dir: Path) -> None:
    """The preset's PPO acts in V_a's 3-D latent space, the env receives the decoded 1-D actions
    inside its bounds, and one update moves the policy."""
    from plls_bench.train.ppo_model import new_model as new_ppo

    cfg = compose_preset("mountaincar_plls_ppo", runs_dir)
    recorder = Recorder(make_vec_env(cfg.env, 2, seed=0))
    venv = wrap_latent(recorder, ensure_representations(cfg))
    model = new_ppo(cfg, venv)
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(total_timesteps=model.n_steps * venv.num_envs)
    assert model.rollout_buffer.actions.shape[-1] == 3 and recorder.actions.shape == (2, 1)
    raw = recorder.venv.action_space
    assert np.all(recorder.actions >= raw.low) and np.all(recorder.actions <= raw.high)
    assert any(not torch.equal(b, a) for b, a in zip(before, model.policy.parameters())), "no update happened"
    venv.close()
