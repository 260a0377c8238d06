"""Results as Jupyter shows them and as tables: ``_repr_html_`` bodies, short reprs, and one
row per sensor for fleets (:func:`fleet_rows`, :func:`to_dataframe`, :func:`write_table`).

Every result class delegates here, so the look is one place. Nothing here imports JAX; pandas
is imported only by :func:`to_dataframe` (and Parquet output), with an error naming the
package to install when it is missing.
"""

from __future__ import annotations

import csv
import math
from html import escape
from pathlib import Path

import numpy as np

from .models.layout import PARAM_NAMES

_COLOURS = {"ok": "#1a7f37", "poorly_determined": "#9a6700", "effects_added": "#1a7f37"}
_STYLE = (
    "<style>.cj table{border-collapse:collapse;font-size:12px;margin:4px 0}"
    ".cj td,.cj th{padding:2px 8px;border-bottom:1px solid #ddd;text-align:right}"
    ".cj th{background:#f6f8fa}.cj td:first-child,.cj th:first-child{text-align:left}"
    ".cj .warn{color:#9a6700}.cj summary{cursor:pointer}</style>"
)


def _fmt(v, digits: int = 6) -> str:
    if v is None:
        return ""
    if isinstance(v, float | np.floating):
        return "nan" if not math.isfinite(float(v)) else f"{float(v):.{digits}g}"
    return escape(str(v))


def _badge(status: str) -> str:
    colour = _COLOURS.get(status, "#cf222e")
    return (
        f'<span style="background:{colour};color:white;border-radius:4px;padding:1px 6px">'
        f"{escape(status)}</span>"
    )


def table(header: list[str], rows: list[list], cell=_fmt, attrs: str = "") -> str:
    """An HTML table (cells escaped by ``cell``; floats to 6 significant digits)."""
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table{attrs}><tr>{head}</tr>{body}</table>"


def _lists(warnings: list[str], notes: list[str]) -> str:
    out = "".join(f'<div class="warn">warning: {escape(w)}</div>' for w in warnings)
    if notes:
        items = "".join(f"<li>{escape(n)}</li>" for n in notes)
        out += f"<details><summary>{len(notes)} notes</summary><ul>{items}</ul></details>"
    return out


def _poorly_determined(names: list[str]) -> str:
    if not names:
        return ""
    return f"<div class='warn'>poorly determined: {escape(', '.join(names))}</div>"


def _card(title: str, status: str, body: str) -> str:
    return f'{_STYLE}<div class="cj"><b>{escape(title)}</b> {_badge(status)}{body}</div>'


# ---------------------------------------------------------------------------------------------
# calibration records


def accel_html(cal) -> str:
    """Paper 1's Table 1 layout (value, standard error, unit), the error before and after,
    the fit, warnings and notes."""
    same = cal.input_units == cal.output_units
    unit_g = "1" if same else f"{cal.input_units}/{cal.output_units}"
    units = [unit_g] * 6 + [cal.input_units] * 3
    rows = [[n, cal.params[i], cal.stderr[i], units[i]] for i, n in enumerate(PARAM_NAMES)]
    summary = (
        f"<div>RMS of (|a| - g)/g: {_fmt(cal.rms_before, 3)} &rarr; {_fmt(cal.rms_after, 3)} "
        f"({escape(cal._improvement())}; {escape(cal._floor_words())}); {cal.n_points} "
        f"{escape(cal.use)} from {cal.n_intervals} static intervals; {escape(cal.solver)}: "
        f"{escape(cal.solver_message)} ({cal.iterations} iterations); condition "
        f"{_fmt(cal.condition, 3)}</div>"
    )
    summary += _poorly_determined(cal.poorly_determined)
    body = table(["parameter", "value", "std. error", "unit"], rows) + summary
    title = f"AccelCalibration ({cal.model}, {cal.input_units} -> {cal.output_units})"
    return _card(title, cal.status, body + _lists(cal.warnings, cal.notes))


def accel_repr(cal) -> str:
    return (
        f"AccelCalibration(status={cal.status!r}, model={cal.model!r}, rms "
        f"{cal.rms_before:.3g} -> {cal.rms_after:.3g}, {cal.n_intervals} intervals, "
        f"units {cal.input_units!r} -> {cal.output_units!r}, source={cal.source!r})"
    )


def mag_html(cal) -> str:
    """Centre with standard errors, W, semi-axes, radius, errors, coverage, model choice."""
    unit = cal.units or "raw"
    label = "hard iron" if cal.sensor == "mag" else "bias"
    rows = [
        [f"center {a} ({label})", v, e, unit]
        for a, v, e in zip("xyz", cal.center, cal.center_stderr, strict=True)
    ]
    rows += [[f"semi-axis {i + 1}", v, None, unit] for i, v in enumerate(cal.semi_axes)]
    rows.append(["radius after", cal.radius, None, unit if cal.field is None else "field"])
    W = table(
        ["W", "x", "y", "z"], [[a, *row] for a, row in zip("xyz", cal.soft_iron, strict=True)]
    )
    summary = (
        f"<div>RMS of (|m| - r)/r: {cal.rms_before_pct:.3f} % &rarr; {cal.rms_after_pct:.3f} %; "
        f"{cal.n_samples} samples, {100 * cal.coverage:.0f} % of the sphere of directions; "
        f"{escape(cal.solver)}: {escape(cal.solver_message)}</div>"
    )
    if len(cal.model_selection) > 1:
        sel = [[m, v.get("bic"), v.get("rms_pct")] for m, v in cal.model_selection.items()]
        summary += table(["model", "BIC", "rms %"], sel)
    how = "std. error (block jackknife)" if cal.honest else "std. error"
    body = table(["parameter", "value", how, "unit"], rows) + W + summary
    title = f"MagCalibration ({cal.sensor}, model {cal.model})"
    return _card(title, cal.status, body + _lists(cal.warnings, cal.notes))


def mag_repr(cal) -> str:
    return (
        f"MagCalibration(status={cal.status!r}, sensor={cal.sensor!r}, model={cal.model!r}, "
        f"rms {cal.rms_before_pct:.3g} % -> {cal.rms_after_pct:.3g} %, {cal.n_samples} samples, "
        f"source={cal.source!r})"
    )


def gyro_html(cal) -> str:
    """C and b with standard errors, the miss between poses before and after beside its
    floor, the noise, each candidate effect's test, warnings and notes."""
    unit_c = f"rad/s per {cal.input_units}"
    rows = [
        [f"C_{r}{c}", cal.matrix[i, j], cal.stderr_matrix[i, j], unit_c]
        for i, r in enumerate("xyz")
        for j, c in enumerate("xyz")
    ]
    rows += [
        [f"b_{a}", v, e, cal.input_units]
        for a, v, e in zip("xyz", cal.bias, cal.stderr_bias, strict=True)
    ]
    summary = (
        f"<div>miss between poses (RMS over {cal.n_motions} motions): {_fmt(cal.rms_before_deg, 3)}"
        f" &rarr; {_fmt(cal.rms_after_deg, 3)} deg (rest-noise floor "
        f"{_fmt(cal.noise_floor_deg, 3)} deg); {cal.n_poses} poses; {escape(cal.solver)}: "
        f"{escape(cal.solver_message)} ({cal.iterations} iterations)</div>"
    )
    effects = [
        [name, "accepted" if e.get("accepted") else "not found", e.get("F"), e.get("p")]
        for name, e in cal.effects.items()
    ]
    if effects:
        summary += table(["candidate effect", "verdict", "F", "p"], effects)
    summary += _poorly_determined(cal.poorly_determined)
    body = table(["parameter", "value", "std. error", "unit"], rows) + summary
    title = f"GyroCalibration ({cal.method}, {cal.input_units} -> rad/s)"
    return _card(title, cal.status, body + _lists(cal.warnings, cal.notes))


def marg_repr(rec) -> str:
    acc = "none" if rec.accel is None else f"{rec.accel_method} {_short_rms(rec.accel)}"
    gyro = "" if rec.gyro is None else f", gyro {rec.gyro.rms_after_deg:.3g} deg"
    return (
        f"MARGRecord(status={rec.status!r}, accel {acc}, mag {rec.mag.model} "
        f"{_short_rms(rec.mag)}, rotation {rec.rotation_deg:.3g} deg ({rec.permutation})"
        f"{gyro}, source={rec.source!r})"
    )


def _short_rms(cal) -> str:
    """'rms 12.2 % -> 4.36 %' for an ellipsoid, 'rms 1.1e-3 -> 1.0e-4' for paper 1's fit."""
    if hasattr(cal, "rms_after_pct"):
        return f"rms {cal.rms_before_pct:.3g} % -> {cal.rms_after_pct:.3g} %"
    return f"rms {cal.rms_before:.3g} -> {cal.rms_after:.3g}"


def marg_html(rec) -> str:
    parts = [f"<div>accelerometer: {escape(rec.accel_method)}</div>"]
    if rec.accel is not None:
        parts.append(rec.accel._repr_html_())
    parts.append(rec.mag._repr_html_())
    parts.append(f"<div>{escape(rec.alignment_text())}</div>")
    if rec.gyro is not None:
        parts.append(rec.gyro._repr_html_())
    return _card("MARGRecord", rec.status, "".join(parts) + _lists(rec.warnings, []))


# ---------------------------------------------------------------------------------------------
# diagnosis


def diagnosis_unit(sensor: str) -> tuple[str, float]:
    """The unit a diagnosis is shown in and the factor from its stored numbers: mg for the
    accelerometer (errors in g), % for the magnetometer (radii), degrees for MARG (radians)."""
    return {"accel": ("mg", 1e3), "mag": ("%", 1e2)}.get(sensor, ("deg", 180 / math.pi))


def diagnosis_repr(d) -> str:
    if d.verdict == "not_possible":
        return f"Diagnosis(sensor={d.sensor!r}, verdict='not_possible', source={d.source!r})"
    u, f = diagnosis_unit(d.sensor)
    return (
        f"Diagnosis(sensor={d.sensor!r}, verdict={d.verdict!r}, effects={d.effects}, rms "
        f"{d.rms_before * f:.3g} -> {d.rms_after * f:.3g} {u} (floor {d.noise_floor * f:.3g}), "
        f"{d.n_observations} {d.observations}, source={d.source!r})"
    )


def diagnosis_html(d) -> str:
    """The steps table (effect added, parameters, RMS, leave-one-out RMS, BIC), the floor and
    the verdict, in the units :meth:`Diagnosis.summary` prints."""
    u, f = diagnosis_unit(d.sensor)
    if d.verdict == "not_possible":
        return _card(f"Diagnosis ({d.sensor})", d.verdict, _lists([], d.notes))
    rows = [
        [s["added_effect"] or "base", s["n_params"], s["rms"] * f, s["loo_rms"] * f, s["bic"]]
        for s in d.steps
    ]
    body = "".join(f"<div><b>found:</b> {escape(x)}</div>" for x in d.findings)
    body += table(["step", "params", f"rms ({u})", f"loo rms ({u})", "BIC"], rows)
    body += (
        f"<div>noise floor {d.noise_floor * f:.4g} {u} (white {d.noise_floor_white * f:.4g}, "
        f"Allan {d.noise_floor_allan * f:.4g}); rms {d.rms_before * f:.4g} &rarr; "
        f"{d.rms_after * f:.4g} {u}; {d.n_observations} {escape(d.observations)}</div>"
    )
    cands = [
        [k + 1, e["effect"], "yes" if e["accepted"] else "no", e.get("delta_bic"),
         e.get("loo_gain"), ", ".join(t for t, ok in e.get("tests", {}).items() if not ok)]
        for k, rnd in enumerate(d.rounds)
        for e in rnd
        if "tests" in e
    ]  # fmt: skip
    if cands:
        body += "<details><summary>candidate effects, round by round</summary>"
        body += table(["round", "effect", "accepted", "dBIC", "loo gain", "failed tests"], cands)
        body += "</details>"
    if d.rejected:
        body += f"<div>{len(d.rejected)} observations rejected as outliers</div>"
    return _card(f"Diagnosis ({d.sensor})", d.verdict, body + _lists([], d.notes))


# ---------------------------------------------------------------------------------------------
# fleets: one row per sensor


def param_names(sensor: str) -> list[str]:
    """The batch parameter vector's names: paper 1's nine, the ellipsoid's centre and W, or
    the gyroscope's C and b."""
    if sensor == "accel":
        return list(PARAM_NAMES)
    if sensor == "gyro":
        return [f"C_{r}{c}" for r in "xyz" for c in "xyz"] + [f"b_{a}" for a in "xyz"]
    return [f"center_{a}" for a in "xyz"] + [f"W_{r}{c}" for r in "xyz" for c in "xyz"]


def fleet_rows(results, sensor: str | None = None) -> list[dict]:
    """Flat rows (one per file) of :func:`calib_jax.fleet.calibrate_files`' result dicts:
    file, status, message, each parameter and its standard error, rms, iterations, points,
    units and the notes joined by '; '."""
    rows = []
    for r in results:
        n = len(r.get("params") or [])
        sens = sensor or ("accel" if n == 9 else "mag")
        row = {"file": r.get("path"), "status": r.get("status"), "message": r.get("message")}
        names = param_names(sens) if n else []
        row.update(zip(names, r.get("params") or [], strict=False))
        row.update({f"se_{k}": v for k, v in zip(names, r.get("stderr") or [], strict=False)})
        keys = ("rms", "rms_before_deg", "noise_floor_deg", "iterations", "n_points")
        for k in (*keys, "static_intervals", "units", "g", "use"):
            if k in r:
                row[k] = r[k]
        row["warnings"] = "; ".join(r.get("warnings") or [])
        row["notes"] = "; ".join(r.get("notes") or [])
        rows.append(row)
    return rows


def to_dataframe(rows: list[dict]):
    """A pandas DataFrame of rows (pandas is needed only here)."""
    try:
        import pandas as pd
    except ImportError:
        raise ImportError(
            "to_dataframe needs pandas: pip install pandas (or write CSV with write_table)"
        ) from None
    return pd.DataFrame(rows)


def write_table(rows: list[dict], path: str | Path) -> Path:
    """Write rows as CSV (any other suffix) or Parquet (``.parquet``: pandas and pyarrow)."""
    path = Path(path)
    if path.suffix.lower() == ".parquet":
        try:
            to_dataframe(rows).to_parquet(path)
        except ImportError as exc:
            raise ValueError(
                f"--table {path}: Parquet needs pandas and pyarrow ({exc}); install them "
                "(pip install pandas pyarrow) or write a .csv"
            ) from None
        return path
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    return path


def batch_repr(kind: str, sensor: str, statuses) -> str:
    """'BatchResult(accel, 4 sensors: 3 ok, 1 failed)'."""
    from collections import Counter

    counts = ", ".join(f"{n} {s}" for s, n in Counter(statuses).most_common())
    return f"{kind}({sensor}, {len(statuses)} sensors: {counts or 'none'})"


def batch_record_html(rec) -> str:
    """The count of usable entries and the first rows of :func:`fleet_rows`."""
    ok, n = int(rec.success.sum()), len(rec)
    head = f"<b>BatchRecord</b> ({escape(rec.sensor)}): {ok} of {n} entries usable"
    return head + rows_html(fleet_rows(rec.entries, rec.sensor))


def _clipped(v, width: int = 48) -> str:
    """A table cell: text longer than ``width`` cut, the whole of it shown on hover."""
    if isinstance(v, str) and len(v) > width:
        return f'<span title="{escape(v)}">{escape(v[: width - 1])}&hellip;</span>'
    return _fmt(v)


def rows_html(rows: list[dict], limit: int = 20) -> str:
    """The first ``limit`` rows as an HTML table that scrolls sideways, long text (messages,
    notes) cut to one line with the whole on hover, and the count of the rest."""
    if not rows:
        return "<div>no rows</div>"
    keys = list(rows[0])
    cells = [[r.get(k) for k in keys] for r in rows[:limit]]
    grid = table(keys, cells, cell=_clipped, attrs=' style="white-space:nowrap"')
    more = f"<div>... {len(rows) - limit} more rows</div>" if len(rows) > limit else ""
    return f'{_STYLE}<div class="cj"><div style="overflow-x:auto">{grid}</div>{more}</div>'
