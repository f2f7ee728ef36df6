"""Option groups shared by several verbs, defined once: the acquisition and its
nuisances (augment, sweep, calibrate), the radar chain (process, simulate) and the
classifiers (train, sweep, baseline), with the choices they offer and the objects
they make (:func:`acquisition_from_args`, :func:`chain_from_args`, :func:`model_params`).
Nothing heavy is imported at module level.
"""
from __future__ import annotations

from .common import count_2, db_at_most_0, finite_float, noise_pair, nonneg_float, nonneg_int, nonneg_pair, positive_int

NUISANCE_PHASES = ("relative", "uniform", "fixed")  # relative = fixed + the sigma_P phase perturbation
ACQUISITION_PHASES = ("fixed", "uniform")  # checked against mdaug.generator.PHASE_TREATMENTS in tests
ACQUISITION_PRESETS = ("published", "measured")
NORMALISATIONS = ("peak", "db", "l2", "none")  # checked against mdaug.radar.NORMALISATIONS in tests
SIGN_POLICIES = ("reflect", "truncate", "keep")  # checked against mdaug.generator.SIGN_POLICIES in tests
DTYPES = ("float32", "float64")


def add_acquisition_options(p, *, relative: bool = True, profile_options: bool = True) -> None:
    """The acquisition (SPEC 3.2): a preset and its terms, all optional (None = not
    given). Shared by augment, sweep and calibrate: add an acquisition option here and
    every verb gets it. ``relative`` offers the published sigma_P phase treatment."""
    g = p.add_argument_group("acquisition (SPEC 3.2; what a measured profile averages and randomises)")
    g.add_argument("--acquisition", choices=ACQUISITION_PRESETS, default=None,
                   help="preset: published = one chirp at the vector's phases (f(x) itself); measured = a "
                        "campaign through the published chain (random phases per frame, 1 bin of sub-bin jitter, "
                        "body return 0-0.3, noise -48..-42 dB, yaw +-15 deg, MTI over 10 frames) (default: the "
                        "data file's, else published)")
    phases = NUISANCE_PHASES if relative else ACQUISITION_PHASES
    g.add_argument("--phases", choices=phases, default=None,
                   help="vibration phases per frame: uniform (random), fixed (the vector's)"
                        + (", relative (published: fixed, and sigma_P perturbs them: phi + N(0, sigma_P |phi|))"
                           if relative else "") + " (default: the preset's)")
    g.add_argument("--ramps", type=positive_int, default=None, metavar="K",
                   help="ramps per frame, averaged incoherently, phases advancing by w x 2.88 ms between ramps "
                        "(default: the data file's ramps_per_frame, else 1)")
    g.add_argument("--range-jitter", type=nonneg_float, default=None, metavar="BINS",
                   help="width of the uniform sub-bin jitter of the target range, FFT bins (default: the preset's)")
    g.add_argument("--carrier", type=nonneg_pair, default=None, metavar="LO,HI",
                   help="return at the carrier (body, hub), uniform in LO..HI x sum(Gamma) (default: the preset's)")
    g.add_argument("--noise-db", type=noise_pair, default=None, metavar="LO,HI|none",
                   help="noise floor, uniform in LO..HI dB relative to an unmodulated carrier line "
                        "(write --noise-db=-48,-42: a leading minus needs the =), or none (default: the preset's)")
    g.add_argument("--yaw-deg", type=nonneg_float, default=None, metavar="DEG",
                   help="yaw uniform in +-DEG mixes roll and pitch amplitudes (default: the preset's)")
    g.add_argument("--mti-depth", type=nonneg_int, default=None, metavar="N",
                   help="MTI over the N previous frames (its residual); 0 = none (default: the preset's)")
    if not profile_options:
        return
    g = p.add_argument_group("profiles")
    g.add_argument("--normalisation", choices=NORMALISATIONS, default="peak",
                   help="normalisation of every profile: peak = 1, dB re peak, unit L2 norm, or none "
                        "(default: %(default)s)")
    g.add_argument("--dtype", choices=DTYPES, default="float32",
                   help="compute precision of f(x): float32 is ~5x faster, error ~1e-7 of the peak "
                        "(default: %(default)s)")


ACQUISITION_FIELDS = {"ramps": "ramps", "range_jitter": "range_jitter_bins", "carrier": "carrier",
                      "noise_db": "noise_db", "yaw_deg": "yaw_deg", "mti_depth": "mti_depth"}


def acquisition_given(args) -> bool:
    """Whether any acquisition option was given on the command line."""
    return any(getattr(args, k, None) is not None for k in ("acquisition", "phases", *ACQUISITION_FIELDS))


def acquisition_from_args(args, base=None):
    """(Acquisition, perturb_phases) from the options over ``base`` (a file's acquisition
    or None): the preset (or base, else published) with every given term replaced.
    ``perturb_phases``: the published sigma_P phase treatment (``--phases relative``,
    the default of the published preset)."""
    from ..generator.acquisition import Acquisition

    if args.acquisition == "measured":
        acq = Acquisition.measured(args.ramps or (base.ramps if base is not None else 1))
    elif args.acquisition == "published":
        acq = Acquisition()
    else:
        acq = base if base is not None else Acquisition()
    changes = {field: getattr(args, opt) for opt, field in ACQUISITION_FIELDS.items()
               if getattr(args, opt, None) is not None}
    if changes.get("noise_db") == "none":
        changes["noise_db"] = None
    phases = getattr(args, "phases", None)
    perturb = phases == "relative" or (phases is None and acq.phases == "fixed" and acq.is_published)
    if phases is not None:
        changes["phases"] = "fixed" if phases == "relative" else phases
    return (acq.replace(**changes) if changes else acq), perturb


def add_chain_options(p) -> None:
    """The radar processing chain (SPEC section 4): process and simulate."""
    from ..radar.chain import EDGE_POLICIES, ORDERS, ChainConfig

    d = ChainConfig()
    g = p.add_argument_group("radar chain (SPEC section 4)")
    g.add_argument("--n-angle", type=count_2, default=d.n_angle, metavar="N",
                   help="angle FFT points across the antennas (default: %(default)s)")
    g.add_argument("--rel-threshold-db", type=db_at_most_0, default=d.rel_threshold_db, metavar="DB",
                   help="a peak counts if it is at least this level, in dB (<= 0) relative to the strongest "
                        "peak (write --rel-threshold-db=-12: a leading minus needs the =) (default: "
                        "%(default)s dB)")
    g.add_argument("--floor-db", type=finite_float, default=d.floor_db, metavar="DB",
                   help="... and at least this many dB above the median noise floor (default: %(default)s dB)")
    g.add_argument("--max-targets", type=positive_int, default=None, metavar="N",
                   help="keep at most this many peaks per MTI frame (default: all that pass)")
    g.add_argument("--edge", choices=EDGE_POLICIES, default=d.edge,
                   help="signatures reaching past the profile's ends: keep them zero-filled, or drop them "
                        "(default: %(default)s)")
    g.add_argument("--order", choices=ORDERS, default=d.order,
                   help="fast: MTI on the raw samples first (identical result, linear steps); image: the "
                        "literal order (default: %(default)s)")


def chain_from_args(args):
    from ..radar.chain import ChainConfig

    return ChainConfig(n_angle=args.n_angle, rel_threshold_db=args.rel_threshold_db, floor_db=args.floor_db,
                       max_targets=args.max_targets, edge=args.edge, order=args.order)


def add_classifier_options(p, *, epochs_default: int = 50, normalisation: bool = True, cnn_only: bool = False) -> None:
    """Classifier settings: train, sweep and baseline (``cnn_only``)."""
    g = p.add_argument_group("CNN options" if cnn_only else "classifier options")
    if normalisation:
        g.add_argument("--normalisation", choices=NORMALISATIONS, default="peak",
                       help="preprocessing shared by training and testing (default: %(default)s)")
    g.add_argument("--epochs", type=positive_int, default=epochs_default,
                   help="CNN training epochs (default: %(default)s)")
    g.add_argument("--batch-size", type=positive_int, default=256, metavar="N",
                   help="CNN batch size, profiles (default: %(default)s)")
    g.add_argument("--patience", type=positive_int, default=None, metavar="EPOCHS",
                   help="CNN early stopping after this many epochs without a better validation loss "
                        "(default: none, train every epoch)")
    from ..classify.base import PRECISIONS

    g.add_argument("--precision", choices=PRECISIONS, default="auto",
                   help="CNN forward passes: bfloat16 autocast (1.5x on CPUs with native bfloat16, the same "
                        "accuracy), float32, or auto = bfloat16 where the CPU has it natively, else float32 "
                        "(default: %(default)s)")
    add_device_option(g)
    if cnn_only:
        return
    g.add_argument("--kernel", default="rbf", choices=("rbf", "linear", "poly", "sigmoid"),
                   help="SVM kernel: rbf = scikit-learn SVC, linear = LinearSVC (fast) (default: %(default)s)")
    g.add_argument("--n-estimators", type=positive_int, default=100, metavar="N",
                   help="XGBoost trees (default: %(default)s)")


def add_device_option(p) -> None:
    """``--device``: where the torch steps (the CNN's training and predictions) run."""
    from ..classify.base import DEVICES

    p.add_argument("--device", choices=DEVICES, default="auto",
                   help="where the CNN trains and predicts: auto = a CUDA GPU when torch sees one, else the CPU "
                        "(default: %(default)s)")


def model_params(args, name: str) -> dict:
    """Classifier parameters from the command line (only those that apply to ``name``)."""
    p = {"normalisation": args.normalisation, "threads": args.threads}
    if name == "cnn":
        p.update(epochs=args.epochs, batch_size=args.batch_size, patience=args.patience, device=args.device,
                 precision=getattr(args, "precision", "float32"))
    elif name == "svm":
        p.update(kernel=args.kernel)
    elif name == "xgb":
        p.update(n_estimators=args.n_estimators)
    return p
