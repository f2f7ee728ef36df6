"""Model files that load without executing code from the file.

A model file is one ZIP archive holding

* ``meta.json``: ``format`` ("mdaug-classifier"), ``format_version``, ``kind``
  (svm / nb / xgb / cnn), ``params`` (constructor arguments, including the
  ``normalisation``), ``classes`` (labels in score order), ``n_features`` (input
  profile length), ``weights`` (the member below), training figures
  (``train_seconds``, CNN ``history`` and ``split_scores``) and the package version;
* the weights, in each library's data-only format: ``model.skops`` (scikit-learn via
  skops, loaded with an explicit list of trusted types), ``model.ubj`` (XGBoost's own
  UBJSON), ``model.pt`` (a torch state dict loaded with ``weights_only=True``).

Any other kind of file, a corrupted archive or a member that does not parse gives a
:class:`mdaug.radar.DataFileError` naming the file.
"""
from __future__ import annotations

import io
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..radar import DataFileError, atomic_write, package_version
from ..radar.npz import check_readable
from .base import ProfileClassifier
from .models import classifier_class

FORMAT = "mdaug-classifier"
FORMAT_VERSION = 1
SKOPS_TRUSTED = ("sklearn.calibration._CalibratedClassifier", "sklearn.calibration._SigmoidCalibration")


def _weights(model: ProfileClassifier) -> tuple[str, bytes]:
    if model.name in ("svm", "nb"):
        import skops.io as sio

        return "model.skops", sio.dumps(model.estimator_)
    if model.name == "xgb":
        return "model.ubj", bytes(model.estimator_.get_booster().save_raw("ubj"))
    if model.name == "cnn":
        import torch

        buf = io.BytesIO()
        torch.save({k: v.detach().cpu().contiguous() for k, v in model.net_.state_dict().items()}, buf)
        return "model.pt", buf.getvalue()
    raise ValueError(f"cannot save a model of kind {model.name!r}")


def save_model(model: ProfileClassifier, path) -> Path:
    """Write a trained classifier to ``path`` (one ZIP, written atomically)."""
    if not isinstance(model, ProfileClassifier):
        raise ValueError(f"save_model expects an mdaug classifier, got {type(model).__name__}")
    model.check_fitted()
    member, blob = _weights(model)
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": model.name,
            "params": model.params(), "classes": model.classes_.tolist(),
            "n_features": model.n_features_in_, "normalisation": model.normalisation,
            "weights": member, "train_seconds": model.train_seconds_,
            "package_version": package_version()}
    if model.name == "cnn":
        meta.update(history=model.history_, split_scores=model.split_scores_, best_epoch=model.best_epoch_)

    def write(fh):
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("meta.json", json.dumps(meta, indent=1))
            zf.writestr(member, blob)

    return atomic_write(path, write)


def _read_archive(path: Path) -> tuple[dict, bytes]:
    check_readable(path, "model file")
    if not zipfile.is_zipfile(path):
        raise DataFileError(f"{path}: not an mdaug model file (expected a ZIP archive written by "
                            f"'mdaug train' / save_model)")
    try:
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            if "meta.json" not in names:
                raise DataFileError(f"{path}: not an mdaug model file (no meta.json; members: {names[:5]})")
            meta = json.loads(zf.read("meta.json"))
            if not isinstance(meta, dict) or meta.get("format") != FORMAT:
                raise DataFileError(f"{path}: meta.json field 'format' is not {FORMAT!r}")
            if meta.get("format_version") != FORMAT_VERSION:
                raise DataFileError(f"{path}: meta.json field 'format_version' is "
                                    f"{meta.get('format_version')!r}, this mdaug reads {FORMAT_VERSION}")
            for key in ("kind", "params", "classes", "n_features", "weights"):
                if key not in meta:
                    raise DataFileError(f"{path}: meta.json lacks field {key!r}")
            if meta["weights"] not in names:
                raise DataFileError(f"{path}: weights member {meta['weights']!r} is missing")
            blob = zf.read(meta["weights"])
    except DataFileError:
        raise
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataFileError(f"{path}: meta.json is not valid JSON ({exc})") from None
    except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, OSError, EOFError, ValueError) as exc:
        raise DataFileError(f"{path}: corrupted model file ({exc})") from None
    return meta, blob


def _restore(model: ProfileClassifier, meta: dict, blob: bytes) -> None:
    if model.name in ("svm", "nb"):
        import skops.io as sio

        untrusted = sio.get_untrusted_types(data=blob)
        refused = sorted(set(untrusted) - set(SKOPS_TRUSTED))
        if refused:
            raise DataFileError(f"types {refused} are not on the trusted list")
        model.estimator_ = sio.loads(blob, trusted=list(untrusted))
    elif model.name == "xgb":
        est = model.new_estimator()
        est.load_model(bytearray(blob))
        model.estimator_ = est
    elif model.name == "cnn":
        import torch

        try:
            state = torch.load(io.BytesIO(blob), weights_only=True, map_location="cpu")
        except Exception as exc:  # torch's own text advises weights_only=False: never do that here
            raise DataFileError(f"weights member {meta['weights']!r} is not a plain tensor state dict "
                                f"({type(exc).__name__}); it may hold Python objects, which mdaug never "
                                "loads: retrain the model or use a trusted copy") from None
        if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
            raise DataFileError(f"weights member {meta['weights']!r} is not a state dict of tensors")
        net = model.build(len(model.classes_))
        net.load_state_dict(state)
        model.net_ = net.to(memory_format=torch.channels_last)
        model.history_ = meta.get("history", [])
        model.split_scores_ = meta.get("split_scores", {})
        model.best_epoch_ = meta.get("best_epoch")


WEIGHTS = {"svm": "model.skops", "nb": "model.skops", "xgb": "model.ubj", "cnn": "model.pt"}
"""The weights member each kind writes."""
CNN_FEATURES = 400  # the CNN's 1 x 20 x 20 input


def _check_meta(meta: dict) -> None:
    """meta.json's fields must agree with each other (DataFileError naming the field)."""
    kind = meta["kind"]
    if kind not in WEIGHTS:
        raise DataFileError(f"meta.json field 'kind' = {kind!r}; expected one of {sorted(WEIGHTS)}")
    if meta["weights"] != WEIGHTS[kind]:
        raise DataFileError(f"meta.json field 'weights' = {meta['weights']!r} disagrees with field 'kind' = "
                            f"{kind!r} (which writes {WEIGHTS[kind]!r})")
    classes = meta["classes"]
    if (not isinstance(classes, list) or len(classes) < 2 or not all(isinstance(c, str) and c for c in classes)
            or len(set(classes)) != len(classes)):
        raise DataFileError(f"meta.json field 'classes' = {classes!r}; expected 2 or more distinct class names")
    n = meta["n_features"]
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise DataFileError(f"meta.json field 'n_features' = {n!r}; expected an integer >= 2 (profile bins)")
    if kind == "cnn" and n != CNN_FEATURES:
        raise DataFileError(f"meta.json field 'n_features' = {n} disagrees with field 'kind' = 'cnn' (a "
                            f"{CNN_FEATURES}-bin input)")
    if not isinstance(meta["params"], dict):
        raise DataFileError("meta.json field 'params' is not a table")
    norm = meta["params"].get("normalisation")
    if "normalisation" in meta and norm is not None and meta["normalisation"] != norm:
        raise DataFileError(f"meta.json field 'normalisation' = {meta['normalisation']!r} disagrees with "
                            f"params.normalisation = {norm!r}")


def _check_restored(model: ProfileClassifier, meta: dict) -> None:
    """The restored weights must have the classes and inputs meta.json states."""
    est = getattr(model, "estimator_", None)
    if est is None:
        return
    n_in = getattr(est, "n_features_in_", None)
    if model.name == "xgb":
        n_in = est.get_booster().num_features()
    n_cls = len(getattr(est, "classes_", ())) or None
    if n_in is not None and int(n_in) != model.n_features_in_:
        raise DataFileError(f"the weights take {int(n_in)}-bin profiles but meta.json field 'n_features' says "
                            f"{model.n_features_in_}")
    if n_cls is not None and n_cls != len(model.classes_):
        raise DataFileError(f"the weights score {n_cls} classes but meta.json field 'classes' lists "
                            f"{len(model.classes_)}")


def load_model(path) -> ProfileClassifier:
    """Read a classifier written by :func:`save_model` (no code from the file runs)."""
    path = Path(path)
    meta, blob = _read_archive(path)
    try:
        _check_meta(meta)
        params = dict(meta["params"])
        if "fractions" in params:
            params["fractions"] = tuple(params["fractions"])
        model = classifier_class(meta["kind"])(**params)
        model.classes_ = np.array([str(c) for c in meta["classes"]])
        model.n_features_in_ = int(meta["n_features"])
        model.train_seconds_ = meta.get("train_seconds")
        _restore(model, meta, blob)
        _check_restored(model, meta)
    except DataFileError as exc:
        raise DataFileError(f"{path}: {exc}") from None
    except Exception as exc:  # each library raises its own types for bad bytes
        raise DataFileError(f"{path}: cannot restore the {meta.get('kind')!r} model "
                            f"({type(exc).__name__}: {exc})") from None
    return model
