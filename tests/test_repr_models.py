"""V_a and V_s architectures from the shipped configs, the VAE loss, and parameter accounting."""
from __future__ import annotations

import pytest
import torch
from torch import nn
from torch.distributions import Normal, kl_divergence

from plls_bench.config import ConfigError
from plls_bench.repr.accounting import architecture_summary, parameter_counts
from plls_bench.repr.models import ActionVAE, StateVAE
from plls_bench.rundirs.composition import compose

# (task, action dim, N_e) from Secs. 5.1-5.3
TASKS = [("mountaincar", 1, 3), ("carracing", 3, 32), ("cheetah", 6, 12)]


@pytest.mark.parametrize(("task", "action_dim", "latent_dim"), TASKS)
def test_action_vae_shapes_follow_the_task_config(task: str, action_dim: int, latent_dim: int) -> None:
    cfg = compose([f"env={task}", "repr/action=vae"])
    vae = ActionVAE(cfg.repr.action, action_dim)
    a = torch.rand(5, action_dim) * 2 - 1
    mu, std = vae.encode(a)
    assert mu.shape == std.shape == (5, latent_dim) and bool((std > 0).all())
    assert vae.decode(mu).shape == (5, action_dim)
    a_hat, mu2, std2 = vae(a)
    assert a_hat.shape == a.shape and torch.equal(mu, mu2) and torch.equal(std, std2)


def test_mountaincar_action_vae_is_the_papers_mlp() -> None:
    vae = ActionVAE(compose(["repr/action=vae"]).repr.action, 1)
    widths = [m.out_features for m in vae.encoder.trunk if isinstance(m, nn.Linear)]
    assert widths == [32, 16, 8] and vae.encoder.mu.out_features == 3  # Sec. 5.1
    widths = [m.out_features for m in vae.decoder.modules() if isinstance(m, nn.Linear)]
    assert widths == [8, 16, 32, 1]


def test_latent_size_override_just_works() -> None:
    cfg = compose(["repr/action=vae", "repr.action.latent_dim=8"])
    vae = ActionVAE(cfg.repr.action, 1)
    assert vae.encode(torch.zeros(2, 1))[0].shape == (2, 8)
    assert vae.decode(torch.zeros(2, 8)).shape == (2, 1)


def test_state_vae_maps_frames_to_32_latents_and_back_to_pixels() -> None:
    cfg = compose(["env=carracing", "repr/state=vae"])
    vae = StateVAE(cfg.repr.state, cfg.env.image_size)
    x = torch.rand(2, 3, 96, 96)
    mu, std = vae.encode(x)
    assert mu.shape == std.shape == (2, 32)
    x_hat = vae.decode(mu)
    assert x_hat.shape == x.shape and bool((x_hat >= 0).all() and (x_hat <= 1).all())  # sigmoid
    convs = [m for m in vae.encoder.trunk if isinstance(m, nn.Conv2d)]
    assert len(convs) == 4 and all(c.stride == (2, 2) for c in convs)  # Sec. 5.2


@pytest.mark.parametrize(("overrides", "key"), [
    (["env=carracing", "repr/state=vae", "repr.state.deconv_kernel_sizes=[4,4,4,4]"], "deconv_kernel_sizes"),
    (["env=carracing", "repr/state=vae", "repr.state.kernel_sizes=[9,9,9,9]"], "repr.state.kernel_sizes"),
    (["env=mountaincar", "repr/state=vae"], "repr.state.kind"),
    (["env=mountaincar", "runner=repr"], "runner=repr needs"),
    (["repr/action=vae", "repr.action.likelihood_std=0"], "repr.action.likelihood_std"),
    (["repr/action=vae", "repr.action.val_fraction=1.0"], "repr.action.val_fraction"),
    (["repr/action=vae", "repr.action.activation=swish"], "repr.action.activation"),
])
def test_bad_representation_configs_are_refused(overrides: list[str], key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace("[", r"\[")):
        compose(overrides)


def test_loss_is_the_negative_elbo_of_eq_3() -> None:
    torch.manual_seed(0)
    vae = ActionVAE(compose(["repr/action=vae"]).repr.action, 1)
    a = torch.rand(64, 1) * 2 - 1
    torch.manual_seed(1)
    terms = vae.loss(a)
    torch.manual_seed(1)
    a_hat, mu, std = vae(a)
    kl = kl_divergence(Normal(mu, std), Normal(0.0, 1.0)).sum(1)
    s = vae.likelihood_std
    expected = ((a_hat - a).pow(2).sum(1) / (2 * s * s) + kl).mean()
    assert torch.allclose(terms["loss"], expected, rtol=1e-5)
    assert torch.allclose(terms["kl"], kl.mean(), rtol=1e-5)
    assert torch.allclose(terms["recon_mse"], (a_hat - a).pow(2).mean())


def test_parameter_counts_by_hand() -> None:
    vae = ActionVAE(compose(["repr/action=vae"]).repr.action, 1)
    policy = nn.Linear(3, 2)
    counts = parameter_counts({"V_a.encoder": vae.encoder, "V_a.decoder": vae.decoder, "policy": policy},
                              trainable=["policy"])
    encoder = (1 * 32 + 32) + (32 * 16 + 16) + (16 * 8 + 8) + 2 * (8 * 3 + 3)   # FC 32-16-8, mu, log_var
    decoder = (3 * 8 + 8) + (8 * 16 + 16) + (16 * 32 + 32) + (32 * 1 + 1)       # FC 8-16-32, output
    assert counts["modules"]["V_a.encoder"] == {"total": encoder, "trainable": 0}
    assert counts["modules"]["V_a.decoder"] == {"total": decoder, "trainable": 0}
    assert counts["modules"]["policy"] == {"total": 8, "trainable": 8}
    assert (counts["total"], counts["trainable"]) == (encoder + decoder + 8, 8)


def test_parameter_counts_share_and_refuse_unknown_names() -> None:
    shared = nn.Linear(4, 4)
    counts = parameter_counts({"a": shared, "b": nn.Sequential(shared, nn.Linear(4, 1))}, trainable=["b"])
    assert counts["total"] == 20 + 5 and counts["trainable"] == 25
    frozen = nn.Linear(4, 4).requires_grad_(False)
    assert parameter_counts({"f": frozen}, trainable=["f"])["trainable"] == 0
    with pytest.raises(KeyError, match="policy"):
        parameter_counts({"a": shared}, trainable=["policy"])


def test_architecture_summary_lists_layers_with_shapes_and_params() -> None:
    cfg = compose(["env=carracing", "repr/state=vae"])
    vae = StateVAE(cfg.repr.state, 96)
    summary = architecture_summary({"V_s.encoder": vae.encoder, "V_s.decoder": vae.decoder},
                                   {"V_s.encoder": torch.zeros(1, 3, 96, 96), "V_s.decoder": torch.zeros(1, 32)})
    encoder, decoder = summary["V_s.encoder"], summary["V_s.decoder"]
    convs = [row for row in encoder if row["type"] == "Conv2d"]
    assert [row["output_shape"][2] for row in convs] == [47, 22, 10, 4]
    assert decoder[-1]["type"] == "Sigmoid" and decoder[-1]["output_shape"] == [1, 3, 96, 96]
    for module, rows in ((vae.encoder, encoder), (vae.decoder, decoder)):
        assert sum(row["params"] for row in rows) == sum(p.numel() for p in module.parameters())
    assert set(encoder[0]) == {"name", "type", "output_shape", "params", "trainable"}
    assert vae.training, "the summary pass must leave the module's mode alone"


def test_va_may_train_longer_than_vs_at_the_same_budget() -> None:
    budget = compose(["env=carracing", "budget=quick"]).budget
    assert budget.epochs_for("action") == budget.repr_action_epochs != budget.epochs_for("state")
    mountaincar = compose(["env=mountaincar", "budget=quick"]).budget
    assert mountaincar.epochs_for("action") == mountaincar.epochs_for("state") == mountaincar.repr_epochs
    with pytest.raises(ConfigError, match="budget.repr_action_epochs"):
        compose(["budget.repr_action_epochs=0"])
