"""The one registry: every table and figure id, the experiment presets (variant ``default``)
that feed it, the run files it reads and the function that builds it. "Where does Fig 18 come
from" is ``python -m plls_bench.report --list`` or one look below."""
from __future__ import annotations

from functools import partial

from plls_bench.report.claims import claims_table as claims
from plls_bench.report.claims import power
from plls_bench.report.evidence.entry_types import BASE_BLUE, VS_GREEN, Entry, Source
from plls_bench.report.figures import architecture as fig_arch
from plls_bench.report.figures import curves as fig_curves
from plls_bench.report.figures import images as fig_images
from plls_bench.report.figures import latent_space as fig_latent
from plls_bench.report.figures import sweep as fig_sweep
from plls_bench.report.tables import comparisons, efficiency, eval_modes
from plls_bench.report.tables import variants as variants_table
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE

S = Source
EVAL = "metrics/eval.jsonl"
MC_PLLS, MC_PPO = S("mountaincar_plls_ppo", "PL-LS + PPO"), S("mountaincar_ppo", "PPO", BASE_BLUE)
# The paper is silent on exploration: Fig. 10 and 11 are drawn under SB3's Gaussian (literal) and gSDE.
MC_PLLS_GSDE = S("mountaincar_plls_ppo_gsde", "PL-LS + PPO (gSDE)")
MC_PPO_GSDE = S("mountaincar_ppo_gsde", "PPO (gSDE)", BASE_BLUE)
MC_ZOO = S("mountaincar_ppo_zoo", "PPO, rl-baselines3-zoo recipe", BASE_BLUE)
CH_SAC = S("cheetah_sac_state", "SAC from states (DBC's SAC core)", BASE_BLUE)
CH_SAC_PIXEL = S("cheetah_sac_pixel", "SAC from pixels (DBC's SAC core and encoder, no bisimulation)", BASE_BLUE)
CR_PLLS, CR_PPO = S("carracing_plls_ppo", "PL-LS + PPO"), S("carracing_ppo", "PPO", BASE_BLUE)
CH_PLLS, CH_DBC = S("cheetah_plls_dbc", "PL-LS + DBC"), S("cheetah_dbc", "DBC", BASE_BLUE)

FIG10 = Entry("fig10", "Fig. 10", "MountainCar, average return (SB3 Gaussian exploration, the literal reading)",
              (MC_PLLS, MC_PPO), fig_curves.return_curves, EVAL)
FIG10_GSDE = Entry("fig10_gsde", "Fig. 10 (gSDE)", "MountainCar, average return (gSDE exploration)",
                   (MC_PLLS_GSDE, MC_PPO_GSDE), fig_curves.return_curves, EVAL)
# CarRacing curves carry the random policy's return (the episodes carracing_data collected V_s's data from).
CR_READS, CR_RANDOM = f"{EVAL}; metrics/dataset.json", ("carracing_data",)
# The verdicts there turn on whether test episodes sample actions (D20): CarRacing draws both readings.
CR_CURVES = partial(fig_curves.return_curves, sampled=True)
FIG18 = Entry("fig18", "Fig. 18", "CarRacing, average return", (CR_PLLS, CR_PPO), CR_CURVES, CR_READS,
              references=CR_RANDOM)
# Fig. 18 under gSDE exploration (rl-baselines3-zoo's CarRacing settings): the paper is silent on exploration.
CR_PLLS_GSDE = S("carracing_plls_ppo_gsde", "PL-LS + PPO (gSDE)")
CR_PPO_GSDE = S("carracing_ppo_gsde", "PPO (gSDE)", BASE_BLUE)
FIG18_GSDE = Entry("fig18_gsde", "Fig. 18 (gSDE)", "CarRacing, average return (gSDE exploration)",
                   (CR_PLLS_GSDE, CR_PPO_GSDE), CR_CURVES, CR_READS, references=CR_RANDOM)
CR_VS = S("carracing_ppo_vs", "PPO + V_s only", VS_GREEN)
CR_VA = S("carracing_ppo_va", "PPO + V_a only", BASE_BLUE)
FIG20 = Entry("fig20", "Fig. 20", "CarRacing ablation, average return", (CR_PLLS, CR_VS, CR_VA),
              CR_CURVES, CR_READS, references=CR_RANDOM)
FIG21 = Entry("fig21", "Fig. 21", "Cheetah run, average return", (CH_PLLS, CH_DBC),
              fig_curves.return_curves, EVAL)

RETURN_COMPARISONS = (FIG10, FIG10_GSDE, FIG18, FIG18_GSDE, FIG20, FIG21)  # the figures whose returns are compared

ENTRIES: tuple[Entry, ...] = (
    Entry("table1", "Table 1", "Hyper-parameters of PL-LS with PPO on MountainCar", (MC_PLLS, MC_PPO),
          partial(efficiency.hyperparameters, paper="table1"), "config.json", kind="table"),
    Entry("table2", "Table 2", "Hyper-parameters of PL-LS with PPO on CarRacing", (CR_PLLS, CR_PPO),
          partial(efficiency.hyperparameters, paper="table2"), "config.json", kind="table"),
    Entry("table3", "Table 3", "Learning efficiency on CarRacing", (CR_PLLS, CR_PPO),
          efficiency.learning_efficiency, f"{PARAMS_FILE}, {EVAL}", kind="table"),
    Entry("fig06", "Fig. 6", "MountainCar V_a, reconstruction loss per epoch", (S("mountaincar_va", "V_a"),),
          partial(fig_curves.loss_curves, model="action", metric="recon_mse"), "metrics/repr_train.jsonl"),
    Entry("fig07", "Fig. 7", "MountainCar, multi-step exploration in V_a's latent space",
          (S("mountaincar_multistep", "study"),), fig_latent.multistep,
          "studies/multistep.npz, metrics/study.json", size=(9.0, 8.0)),
    Entry("fig08", "Fig. 8", "MountainCar, one-step exploration in V_a's latent space",
          (S("mountaincar_onestep", "study"),), fig_latent.onestep,
          "studies/onestep.npz, metrics/study.json", size=(9.0, 8.0)),
    Entry("fig09", "Fig. 9", "MountainCar, generalisation over actions and exploration over states",
          (S("mountaincar_generalisation", "study"),), fig_latent.generalisation,
          "studies/generalisation.npz, metrics/study.json", size=(13.0, 4.5)),
    FIG10,
    FIG10_GSDE,
    Entry("fig11", "Fig. 11", "MountainCar, the learned PL-LS + PPO policy (gSDE exploration)", (MC_PLLS_GSDE,),
          fig_images.filmstrip, "filmstrip/frames.npz, filmstrip/filmstrip.json", size=(12.0, 6.0)),
    Entry("fig11_gaussian", "Fig. 11 (Gaussian)", "MountainCar, the PL-LS + PPO policy (SB3 Gaussian exploration)",
          (MC_PLLS,), fig_images.filmstrip, "filmstrip/frames.npz, filmstrip/filmstrip.json", size=(12.0, 6.0)),
    Entry("fig12", "Fig. 12", "Structure of V_s", (S("carracing_vs", "V_s"),), fig_arch.architecture,
          f"{ARCHITECTURE_FILE}, {PARAMS_FILE}", size=(14.0, 5.0)),
    Entry("fig13", "Fig. 13", "CarRacing V_s, training loss per epoch", (S("carracing_vs", "V_s"),),
          partial(fig_curves.loss_curves, model="state", metric="loss"), "metrics/repr_train.jsonl"),
    Entry("fig14", "Fig. 14", "CarRacing, V_s reconstructions", (S("carracing_vs", "V_s"),),
          fig_images.state_reconstructions, "samples/state_reconstructions.npz", size=(12.0, 3.8)),
    Entry("fig15", "Fig. 15", "CarRacing V_a, reconstruction loss per epoch", (S("carracing_va", "V_a"),),
          partial(fig_curves.loss_curves, model="action", metric="recon_mse"), "metrics/repr_train.jsonl"),
    Entry("fig16", "Fig. 16", "CarRacing, V_a's reconstructions of the first test actions",
          (S("carracing_va", "V_a"),), fig_images.action_reconstructions,
          "samples/action_reconstructions.npz", size=(9.0, 6.0)),
    Entry("fig17", "Fig. 17", "Network structure of PL-LS + PPO and of plain PPO", (CR_PLLS, CR_PPO),
          fig_arch.architecture, f"{ARCHITECTURE_FILE}, {PARAMS_FILE}", size=(14.0, 8.0)),
    FIG18,
    FIG18_GSDE,
    Entry("fig19", "Fig. 19", "CarRacing, the learned PL-LS + PPO policy", (CR_PLLS,), fig_images.filmstrip,
          "filmstrip/frames.npz, filmstrip/filmstrip.json", size=(12.0, 6.0)),
    FIG20,
    FIG21,
    Entry("fig22", "Fig. 22", "Cheetah run, the learned PL-LS + DBC policy", (CH_PLLS,), fig_images.filmstrip,
          "filmstrip/frames.npz, filmstrip/filmstrip.json", size=(12.0, 6.0)),
    # An ablation the paper reports only in words (Sec. 5.2: N_e = 32 "performs the best"); the arms are the
    # values of conf/sweep/ne.yaml: the preset's own runs for 32, the override's variant for the others.
    Entry("sweep_ne", "Sec. 5.2 (N_e sweep)", "CarRacing, PL-LS + PPO against the size N_e of V_a's latent action",
          (CR_PLLS,), partial(fig_sweep.sweep_figure, sweep="ne"), f"{EVAL}; metrics/repr_test.json",
          size=(15.0, 4.8)),
    # Not the paper's: every variant dir found (reproduce --override, a sweep value) beside its preset's default,
    # with a figure per preset that has variants (figures/variants_<preset>.*) and an index line per variant.
    Entry("variants", "Variants", "Every variant found, beside its preset's default", (), variants_table.variants_view,
          f"{EVAL} of every <preset>/<variant> dir of the runs and records", kind="table"),
    Entry("stats", "Return statistics", "IQM, mean and probability of improvement for every return comparison",
          tuple(dict.fromkeys(s for e in RETURN_COMPARISONS for s in e.sources)),
          partial(comparisons.return_statistics, comparisons=RETURN_COMPARISONS), EVAL, kind="table"),
    # Not the paper's: the two readings of every PPO arm's test episodes (D20), per exploration setting, and
    # of the N_e sweep's other values (N_e = 3 and 16 score when they sample, near zero on the latent mean).
    Entry("eval_modes", "Evaluation modes", "Acting on the mean or sampling actions, per PPO arm",
          (MC_PLLS, MC_PPO, MC_PLLS_GSDE, MC_PPO_GSDE, MC_ZOO, CR_PLLS, CR_PPO, CR_VS, CR_VA, CR_PLLS_GSDE,
           CR_PPO_GSDE), partial(eval_modes.evaluation_modes, sweeps=("ne",)), EVAL, kind="table"),
    Entry("claims", "Paper vs suite", "Every quantitative claim of the paper beside the suite's value",
          (MC_PLLS, MC_PPO, MC_PLLS_GSDE, MC_PPO_GSDE, MC_ZOO, CR_PLLS, CR_PPO, CR_VS, CR_VA, CH_PLLS, CH_DBC,
           CH_SAC, CH_SAC_PIXEL, S("mountaincar_va", "V_a"), S("carracing_va", "V_a")),
          claims.claims_table, "every file above; results/paper/claims.csv", kind="table"),
    Entry("power", "Power", "Trials per arm each comparison claim needs for 80% power, and what they cost",
          (MC_PLLS, MC_PPO, MC_PLLS_GSDE, MC_PPO_GSDE, CR_PLLS, CR_PPO, CR_VS, CR_VA, CH_PLLS, CH_DBC),
          power.power_table, f"{EVAL}; results/paper/claims.yaml; bench/throughput.json", kind="table"),
)
BY_ID = {entry.id: entry for entry in ENTRIES}
assert len(BY_ID) == len(ENTRIES), "duplicate registry id"


def builder_name(entry: Entry) -> str:
    """``module:function`` of an entry's build, with a partial's keywords."""
    build, keywords = entry.build, ""
    if isinstance(build, partial):
        keywords = "(" + ", ".join(f"{k}={_keyword(v)}" for k, v in build.keywords.items()) + ")"
        build = build.func
    return f"{build.__module__}:{build.__qualname__}{keywords}"


def _keyword(value: object) -> str:
    if isinstance(value, tuple):
        return "(" + ", ".join(getattr(v, "id", repr(v)) for v in value) + ")"
    return repr(value)
