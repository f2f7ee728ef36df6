"""The CNN's device: "auto" (a GPU when torch sees one, else the CPU), "cpu" or "cuda",
for every torch step (train, evaluate, baseline, run); not saved with the model; a
'cuda' request without a GPU is refused before any work."""
import numpy as np
import pytest
import torch

from mdaug.classify import load_model, make_classifier, save_model
from mdaug.classify.cnn import CNNClassifier, resolve_device
from mdaug.radar import atomic_savez

NO_GPU = not torch.cuda.is_available()


def _data(n=80, seed=0):
    rng = np.random.default_rng(seed)
    y = np.repeat(["HELI", "QUAD"], n // 2)
    x = np.abs(rng.normal(0.1, 0.05, (n, 400)))
    x[:, 200] = 1.0
    x[y == "QUAD", 215] += 0.6
    return x, y


def test_auto_is_the_gpu_when_present_else_the_cpu():
    assert resolve_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")
    assert resolve_device("cpu") == "cpu"
    with pytest.raises(ValueError, match="device must be one of"):
        CNNClassifier(device="gpu")


@pytest.mark.skipif(not NO_GPU, reason="this machine has a GPU")
def test_cuda_without_a_gpu_is_refused_in_words():
    with pytest.raises(ValueError, match="torch sees no CUDA GPU"):
        resolve_device("cuda")


def test_the_device_is_not_saved_and_a_loaded_model_runs_where_asked(tmp_path):
    x, y = _data()
    cpu = make_classifier("cnn", random_state=1, epochs=2, progress=False, device="cpu").fit(x, y)
    auto = make_classifier("cnn", random_state=1, epochs=2, progress=False).fit(x, y)
    if NO_GPU:  # auto is the CPU here: the same model from the same seed
        assert np.array_equal(cpu.predict_proba(x), auto.predict_proba(x))
    save_model(cpu, tmp_path / "m.zip")
    back = load_model(tmp_path / "m.zip")
    assert "device" not in cpu.params() and back.device == "auto"
    back.device = "cpu"
    assert np.allclose(back.predict_proba(x), cpu.predict_proba(x), atol=1e-6)


@pytest.mark.skipif(not NO_GPU, reason="this machine has a GPU")
@pytest.mark.parametrize("verb", ["train", "evaluate", "baseline", "run"])
def test_every_torch_verb_takes_device_and_refuses_cuda_without_a_gpu(verb, tmp_path, refused):
    x, y = _data()
    atomic_savez(tmp_path / "d.npz", profiles=x, labels=y)
    if verb == "evaluate":
        save_model(make_classifier("cnn", random_state=1, epochs=1, progress=False).fit(x, y), tmp_path / "m.zip")
    argv = {"train": ["train", str(tmp_path / "d.npz"), "--model", "cnn", "--out", str(tmp_path / "o" / "c.zip")],
            "evaluate": ["evaluate", str(tmp_path / "m.zip"), str(tmp_path / "d.npz")],
            "baseline": ["baseline", str(tmp_path / "d.npz"), "--out", str(tmp_path / "o" / "b.zip")],
            "run": ["run", "--quick", "--out", str(tmp_path / "o" / "study")]}[verb]
    (tmp_path / "o").mkdir()
    refused(argv + ["--device", "cuda"], tmp_path, tmp_path / "o", ["cuda", "no CUDA GPU"])


def test_evaluate_on_the_cpu(tmp_path, capsys):
    from mdaug.cli import main

    x, y = _data()
    atomic_savez(tmp_path / "d.npz", profiles=x, labels=y)
    assert main(["train", str(tmp_path / "d.npz"), "--model", "cnn", "--epochs", "2", "--device", "cpu",
                 "--allow-degenerate", "--out", str(tmp_path / "c.zip")]) == 0  # two epochs: about the device only
    assert main(["evaluate", str(tmp_path / "c.zip"), str(tmp_path / "d.npz"), "--n-boot", "0",
                 "--device", "cpu"]) == 0
    assert "balanced accuracy" in capsys.readouterr().out


def test_bfloat16_autocast_is_opt_in_reproducible_and_saved(tmp_path):
    x, y = _data()
    with pytest.raises(ValueError, match="precision must be one of"):
        CNNClassifier(precision="float16")
    assert CNNClassifier().precision == "float32"
    a = make_classifier("cnn", random_state=2, epochs=2, progress=False, device="cpu", precision="bfloat16").fit(x, y)
    b = make_classifier("cnn", random_state=2, epochs=2, progress=False, device="cpu", precision="bfloat16").fit(x, y)
    f = make_classifier("cnn", random_state=2, epochs=2, progress=False, device="cpu").fit(x, y)
    assert np.array_equal(a.predict_proba(x), b.predict_proba(x))  # the same seed, the same model
    assert not np.array_equal(a.predict_proba(x), f.predict_proba(x))  # bfloat16 did run
    save_model(a, tmp_path / "bf16.zip")
    back = load_model(tmp_path / "bf16.zip")
    assert back.precision == "bfloat16"
    assert np.array_equal(back.predict_proba(x), a.predict_proba(x))


def test_auto_precision_is_bfloat16_only_where_the_cpu_has_it_natively():
    from mdaug.classify.cnn import resolve_precision

    native = bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    assert resolve_precision("auto", "cpu") == ("bfloat16" if native else "float32")
    assert resolve_precision("auto", "cuda") == "float32"
    assert resolve_precision("float32", "cpu") == "float32" and resolve_precision("bfloat16", "cpu") == "bfloat16"
    with pytest.raises(ValueError, match="precision must be one of"):
        CNNClassifier(precision="fp16")


def test_auto_precision_trains_saves_and_predicts(tmp_path):
    """A CNN with precision 'auto' learns the easy toy task, saves 'auto' (resolved where it
    runs) and the loaded model predicts the same labels."""
    x, y = _data(400)
    m = make_classifier("cnn", random_state=1, epochs=20, batch_size=32, precision="auto", device="cpu",
                        progress=False).fit(x, y)
    assert np.mean(m.predict(x) == y) > 0.9
    save_model(m, tmp_path / "m.zip")
    back = load_model(tmp_path / "m.zip")
    assert back.precision == "auto"
    assert np.array_equal(back.predict(x), m.predict(x))
