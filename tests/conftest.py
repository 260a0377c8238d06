"""Shared set-up: float64 on, shared data, tolerances in one place (each with its reason)."""

from __future__ import annotations

import gc
import os
import shutil
import tempfile
from pathlib import Path

import jax

# One fresh persistent compilation cache for the whole run, inherited by its xdist workers and
# the CLI subprocesses and notebook kernels they start: a function compiled by one module or
# worker is reloaded from disk by the next (after jax.clear_caches() too), and the user's own
# cache is never touched by the tests. The process that made it removes it at the end (a full
# run leaves about 50 MB).
_OWN_CACHE = None
if "CALIB_JAX_CACHE_DIR" not in os.environ:
    _OWN_CACHE = os.environ["CALIB_JAX_CACHE_DIR"] = tempfile.mkdtemp(prefix="calib_jax_test_")
from calib_jax.runtime import configure  # noqa: E402

configure()
jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile(
    "ci",
    max_examples=12,
    deadline=None,  # the first example pays the JAX compile
    derandomize=True,  # CI must be reproducible: the same examples on every run
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile("ci")

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


class Tol:
    """Tolerances, each with the reason it has this size."""

    # Solvers that all reach the same minimum of a smooth float64 problem agree on chi2 to a few
    # ulps of accumulated round-off over thousands of terms.
    CHI2_REL = 1e-9
    # Parameters at the minimum are determined to ~sqrt(eps * cond); with cond ~ 10-100 for
    # well-posed 48-pose data that is ~1e-7 relative in the worst case; observed ~1e-10.
    PARAM_REL = 1e-7
    # Central finite differences with step h ~ 1e-6 have truncation error O(h^2 f''') ~ 1e-10
    # and round-off O(eps / h) ~ 1e-10 on O(1) residuals.
    FD_ABS = 1e-7
    # Parameter recovery: estimates should lie within a few standard errors of the truth
    # (5 sigma: a false alarm rate of ~6e-7 per parameter).
    N_SIGMA = 5.0


_PEAK = {"maps": 0, "rss_gb": 0.0, "clears": 0, "modules": 0}  # this process's, for the summary
_PEAKS_ENV = "CALIB_JAX_TEST_PEAKS"  # a folder the run's processes leave their _PEAK in
_OWN_PEAKS = None
if _PEAKS_ENV not in os.environ:  # the first process (the xdist controller); workers inherit
    _OWN_PEAKS = os.environ[_PEAKS_ENV] = tempfile.mkdtemp(prefix="calib_jax_peaks_")
_RSS_BUDGET_GB = 4.0


def _mapped_regions() -> int | None:
    try:
        with open("/proc/self/maps") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux
        return None


def _map_limit() -> int | None:
    try:
        return int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return None


def _rss_gb() -> float | None:
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e9


@pytest.fixture(scope="module", autouse=True)
def _release_compiled_code():
    """Free every compiled XLA executable after a test module once this process holds many.

    Each executable keeps about nine memory maps (its JIT-compiled code and data) for as long as
    a jit cache holds it, and module-level ``jax.jit`` objects hold theirs for the whole run.
    The full suite compiles thousands of functions: in one process it reached Linux's
    ``vm.max_map_count`` (65,530) and LLVM segfaulted inside a compile (CI exit 139, in
    tests/test_pipeline.py). ``jax.clear_caches()`` drops them. It also drops what the next
    modules would reuse (traced and lowered programs, the runtime's exported-program
    wrappers), which they then rebuild (issue 17's profile of the suite, clearing after every
    module: tracing 201 s, lowering 152 s, the wrappers 170 s in 367 compiles). So the caches
    are cleared only when the process holds a third of the map limit or 4 GB of memory, and
    always where neither can be read.
    """
    yield
    _PEAK["modules"] += 1
    n, limit, rss = _mapped_regions(), _map_limit(), _rss_gb()
    if n is not None:
        _PEAK["maps"] = max(_PEAK["maps"], n)
    if rss is not None:
        _PEAK["rss_gb"] = max(_PEAK["rss_gb"], rss)
    if n is None or limit is None or rss is None or n > limit // 3 or rss > _RSS_BUDGET_GB:
        jax.clear_caches()
        gc.collect()
        _PEAK["clears"] += 1


def pytest_sessionfinish(session):
    """Each process (an xdist worker too) leaves its peaks in the run's folder for them."""
    folder = os.environ.get(_PEAKS_ENV)
    if folder and _PEAK["modules"]:
        line = " ".join(
            f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in _PEAK.items()
        )
        Path(folder, f"peaks-{os.getpid()}.txt").write_text(line + "\n")


def pytest_unconfigure(config):
    for own in (_OWN_CACHE, _OWN_PEAKS):
        if own is not None:
            shutil.rmtree(own, ignore_errors=True)


def pytest_terminal_summary(terminalreporter):
    """Per process: the most memory maps and memory after a module, and how often the
    compiled code was released (against the map limit that crashed CI)."""
    folder = os.environ.get(_PEAKS_ENV)
    peaks = sorted(Path(folder).glob("peaks-*.txt")) if folder else []
    if peaks:
        terminalreporter.write_line(
            f"compiled-code release (vm.max_map_count {_map_limit()}): "
            + "; ".join(p.read_text().strip() for p in peaks)
        )


@pytest.fixture(scope="session")
def tol() -> type[Tol]:
    return Tol


def shared_file(rel: str) -> Path:
    path = SHARED_DATA / rel
    if not path.exists():
        pytest.skip(f"shared data not present: {path}")
    return path


@pytest.fixture(scope="session")
def sim48():
    """A 48-pose simulated log with known truth (input units = g, noise 2 mg)."""
    from calib_jax.simulate import random_params, simulate_accel

    p = random_params(7, gain_spread=0.05, nonorth_spread=0.02, bias_spread=0.05)
    return simulate_accel(p, samples_per_pose=60, transition_samples=40, noise=2e-3, rng=7)


@pytest.fixture(scope="session")
def rng():
    return np.random.default_rng(1234)


@pytest.fixture
def default_sigint():
    """Python's own SIGINT handling for a test that presses a real Ctrl-C: the default
    handler, SIGINT not blocked. Yields what the worker process had before (a fresh-clone CI
    run on this machine twice saw the recorder's Ctrl-C tests run to their time limit, as if
    SIGINT were ignored or blocked there; the assertion messages print this state)."""
    import signal

    before = signal.getsignal(signal.SIGINT)
    blocked = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT])
    try:
        yield f"SIGINT handler before the test: {before!r}, blocked: {blocked}"
    finally:
        signal.signal(signal.SIGINT, before)
        if blocked:
            signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGINT])


@pytest.fixture(autouse=True)
def _unchecked_if_wrong_types(request):
    """Tests marked ``wrong_types`` pass arguments that break calib_jax's annotations on
    purpose, to check calib_jax's own error message (what a user without a type checker gets);
    jaxtyping's runtime checker (pyproject addopts) would stop them first, so it is off for
    them."""
    if request.node.get_closest_marker("wrong_types") is None:
        yield
        return
    import jaxtyping

    before = jaxtyping.config.jaxtyping_disable
    jaxtyping.config.update("jaxtyping_disable", True)
    try:
        yield
    finally:
        jaxtyping.config.update("jaxtyping_disable", before)


# The longest items first (seconds each on this 2-core machine, from --durations): started last,
# notebook 05 alone (3-4 min) ran while the other worker sat idle at the end of the run. With
# them first, pytest-xdist's work stealing spreads the short tests around them.
_LONGEST_FIRST = (
    "test_notebooks.py::test_notebook_runs[05_in_a_jax_pipeline.ipynb]",
    "test_notebooks.py::test_notebook_runs[03_close_the_loop.ipynb]",
    "test_readme_examples.py::test_python_blocks_run_as_written[docs/pipeline.md]",
    "test_notebooks.py::test_notebook_runs[02_magnetometer_marg.ipynb]",
    "test_notebooks.py::test_notebook_runs[07_fleet.ipynb]",
)


def pytest_collection_modifyitems(config, items):
    rank = {name: k for k, name in enumerate(_LONGEST_FIRST)}

    def key(item):
        return rank.get(item.nodeid.removeprefix("tests/"), len(rank))

    items.sort(key=key)  # stable: everything else keeps its order
