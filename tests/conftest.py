"""Test configuration: the hypothesis profile, loading examples and benchmarks."""
import importlib
import importlib.util
import os
import sys
from pathlib import Path

from hypothesis import settings

# CI runs the property tests on hypothesis' fixed example sequence, so a
# submission is judged on the same node sets every time; local runs draw new
# ones (and keep failures in the example database).
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(name):
    """Import examples/<name>.py (running its default computation)."""
    sys.path.insert(0, str(EXAMPLES))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.pop(0)


BENCHMARKS = EXAMPLES.parent / "benchmarks"


def load_benchmark(name):
    """Import benchmarks/<name>.py under the name bench_<name> (its studies
    run only when called)."""
    spec = importlib.util.spec_from_file_location("bench_" + name, BENCHMARKS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod
