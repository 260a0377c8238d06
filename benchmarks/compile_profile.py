"""Where the test suite's time goes: every XLA compile of a pytest run, by program and by test.

As a pytest plugin it records, in each worker, every ``compile_or_get_cached`` call (the
program's name, seconds, whether JAX's persistent cache hit, the test that caused it, the
cache key), JAX's own compile events (tracing, lowering, backend compile) per test file, and
every eager JAX operation (a primitive applied outside jit: a dispatch and a small program
each) with the test and the first line of ours that ran it; each worker writes
``<pid>.json`` into ``$COMPILE_PROFILE_DIR`` (default ``/tmp/calib_jax_compile_profile``).
Run as a script it sums those files.

    PYTHONPATH=benchmarks .venv/bin/python -m pytest -p compile_profile
    .venv/bin/python benchmarks/compile_profile.py [DIR]

Notebook kernels and CLI subprocesses are other processes: their compiles are not counted.
It wraps private JAX functions (``jax._src.compiler``, jax 0.10): a profiling aid, never
imported by calib_jax or its tests.
"""

from __future__ import annotations

import collections
import json
import os
import sys
import time
from pathlib import Path

OUT = Path(os.environ.get("COMPILE_PROFILE_DIR", "/tmp/calib_jax_compile_profile"))
_COMPILES: list[tuple[str, float, bool | None, str, str | None]] = []
_EVENTS: dict[str, dict[str, float]] = {}
_TEST = ["<collect>"]
# eager JAX operations (one primitive applied outside jit, each a dispatch and a small program
# of its own): per test and the first line of ours that caused it, [count, seconds]
_EAGER: dict[str, list] = {}
_OURS = ("/calib_jax/", "/tests/", "/docs/", "/notebooks/", "/benchmarks/")


def _install() -> None:
    import jax.monitoring
    from jax._src import compiler

    compile_or_get_cached, cache_read = compiler.compile_or_get_cached, compiler._cache_read
    last = {}

    def read(module_name, cache_key, *args, **kwargs):
        out = cache_read(module_name, cache_key, *args, **kwargs)
        last.update(hit=out[0] is not None, key=cache_key)
        return out

    def compile_(backend, computation, *args, **kwargs):
        last.clear()
        t = time.perf_counter()
        try:
            return compile_or_get_cached(backend, computation, *args, **kwargs)
        finally:
            name = str(computation.operation.attributes["sym_name"]).strip('"')
            seconds = time.perf_counter() - t
            _COMPILES.append((name, seconds, last.get("hit"), _TEST[0], last.get("key")))

    def listen(event, duration, **_):
        per_file = _EVENTS.setdefault(event, {})
        test_file = _TEST[0].split("::")[0]
        per_file[test_file] = per_file.get(test_file, 0.0) + duration

    compiler.compile_or_get_cached, compiler._cache_read = compile_, read

    from jax._src import core

    process_primitive = core.EvalTrace.process_primitive
    programs = ("call_exported", "jit", "pjit")  # whole programs (jit, runtime.disk_jit)

    def eager(self, prim, args, params, /):
        if prim.name in programs:
            return process_primitive(self, prim, args, params)
        t = time.perf_counter()
        try:
            return process_primitive(self, prim, args, params)
        finally:
            f = sys._getframe(1)
            while f is not None and (
                "site-packages" in f.f_code.co_filename
                or not any(o in f.f_code.co_filename for o in _OURS)
            ):
                f = f.f_back
            site = "?" if f is None else f"{f.f_code.co_filename.split('/')[-1]}:{f.f_lineno}"
            row = _EAGER.setdefault(f"{_TEST[0]} @ {site}", [0, 0.0])
            row[0] += 1
            row[1] += time.perf_counter() - t

    core.EvalTrace.process_primitive = eager
    jax.monitoring.register_event_duration_secs_listener(listen)


def pytest_configure(config):
    _install()


def pytest_runtest_setup(item):
    _TEST[0] = item.nodeid + "::setup"


def pytest_runtest_call(item):
    _TEST[0] = item.nodeid


def pytest_unconfigure(config):
    OUT.mkdir(parents=True, exist_ok=True)
    out = {"compiles": _COMPILES, "events": _EVENTS, "eager": _EAGER}
    (OUT / f"{os.getpid()}.json").write_text(json.dumps(out))


def summary(folder: Path) -> None:
    compiles, events, eager = [], collections.Counter(), {}
    for f in sorted(folder.glob("*.json")):
        d = json.loads(f.read_text())
        compiles += d["compiles"]
        for event, per_file in d["events"].items():
            events[event] += sum(per_file.values())
        for where, (n, sec) in d.get("eager", {}).items():
            eager[where] = [eager.get(where, [0, 0.0])[0] + n, eager.get(where, [0, 0.0])[1] + sec]
    misses = [c for c in compiles if c[2] is False]
    keys, miss_s = len({c[4] for c in misses}), sum(c[1] for c in misses)
    print(f"{len(compiles)} compiles, {sum(c[1] for c in compiles):.0f} s")
    print(f"persistent-cache misses: {len(misses)} ({miss_s:.0f} s), {keys} keys")
    for event, seconds in events.most_common():
        print(f"{seconds:8.1f} s  {event}")
    for title, key in (("program", 0), ("test file", 3)):
        total = collections.defaultdict(lambda: [0, 0.0])
        for c in compiles:
            k = c[key].split("::")[0] if key == 3 else c[key]
            total[k][0] += 1
            total[k][1] += c[1]
        print(f"\nby {title} (seconds, compiles)")
        for k, (n, s) in sorted(total.items(), key=lambda kv: -kv[1][1])[:15]:
            print(f"{s:8.1f} {n:5d}  {k}")
    if eager:
        n_all, s_all = sum(v[0] for v in eager.values()), sum(v[1] for v in eager.values())
        print(f"\neager operations: {n_all} in {s_all:.0f} s; by test and the line that ran them")
        for k, (n, s) in sorted(eager.items(), key=lambda kv: -kv[1][1])[:25]:
            print(f"{s:8.1f} {n:7d}  {k}")


if __name__ == "__main__":
    summary(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
