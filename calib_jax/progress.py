"""Progress bars for long work: fleets, diagnosis rounds with their null tests, recording.

One helper, :func:`progress_bar`, so every path shows the same ``tqdm.auto`` bar (a widget in
Jupyter, a line on a terminal) and obeys the same rule: ``enabled=None`` shows it on a
terminal or in a notebook kernel and hides it when output goes to a file or a pipe (a CI log,
``> out.txt``); ``True`` / ``False`` force it.
"""

from __future__ import annotations

import sys


def in_notebook() -> bool:
    """True inside a Jupyter kernel (not merely when IPython or ipykernel is imported, as
    they are in a test runner that executes notebooks)."""
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    return type(shell).__name__ == "ZMQInteractiveShell"


def progress_bar(total: int | None, enabled: bool | None, desc: str, unit: str = "file"):
    """A ``tqdm.auto`` bar of ``total`` ``unit`` (None: a counter without an end).

    tqdm's monitor thread is not started (it only retunes ``miniters`` of stalled bars, and a
    thread left behind in the caller's process is a side effect)."""
    from tqdm.auto import tqdm

    class Bar(tqdm):
        monitor_interval = 0

    if enabled is None:
        enabled = sys.stderr.isatty() or in_notebook()
    return Bar(total=total, desc=desc, unit=unit, disable=not enabled, leave=True)


def finish(bar) -> None:
    """Close a bar; one that stopped before its ``total`` (a diagnosis that converged in two of
    six rounds) gets what was done as its total, so it reads complete, not stalled."""
    if bar.total is not None and bar.n < bar.total:
        bar.total = bar.n
        bar.refresh()
    bar.close()
