"""The benchmarks (run on demand, never by the suite) still import against today's
API: each module under tests/benchmarks loads, without running, and has a ``main``."""
import subprocess
import sys
from pathlib import Path

BENCHMARKS = sorted((Path(__file__).parent / "benchmarks").glob("*.py"))

LOAD = """
import importlib.util, sys
bad = []
for path in sys.argv[1:]:
    spec = importlib.util.spec_from_file_location("bench_" + path.rsplit("/", 1)[-1][:-3], path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        bad.append(f"{path}: {type(exc).__name__}: {exc}")
        continue
    if not callable(getattr(module, "main", None)):
        bad.append(f"{path}: no main()")
print("\\n".join(bad))
"""


def test_every_benchmark_imports_against_todays_api():
    assert len(BENCHMARKS) >= 10
    out = subprocess.run([sys.executable, "-c", LOAD, *map(str, BENCHMARKS)], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "", out.stdout
