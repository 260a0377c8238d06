"""Screenshots of the results as a notebook shows them (docs/jupyter.md), to check by eye.

Writes each result's ``_repr_html_`` (and a fleet's DataFrame as pandas shows it in Jupyter,
cells cut at 50 characters) as an HTML page under docs/jupyter/, then renders each page to PNG
with WeasyPrint and pypdfium2 (not dependencies of calib_jax: ``pip install weasyprint
pypdfium2``; WeasyPrint's CSS is not a browser's, so spacing differs a little from Jupyter).

Run: ``.venv/bin/python docs/jupyter_screenshots.py`` (about a minute).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import calib_jax as cj  # noqa: E402
from calib_jax.diagnose import diagnose_accel  # noqa: E402
from calib_jax.fleet import calibrate_files, to_dataframe  # noqa: E402
from calib_jax.marg import calibrate_marg_log  # noqa: E402
from calib_jax.simulate import random_params, simulate_accel  # noqa: E402

OUT = Path(__file__).resolve().parent / "jupyter"
PAGE = (
    "<html><head><meta charset='utf-8'></head>"
    "<body style='font-family:sans-serif;font-size:12px;width:900px'>{}</body></html>"
)


def fleet_files(tmp: str) -> list[str]:
    """Four simulated accelerometer logs and one broken file."""
    paths = []
    for k in range(4):
        s = simulate_accel(random_params(k), samples_per_pose=100, transition_samples=20, rng=k)
        path = f"{tmp}/imu{k}.csv"
        t = np.arange(len(s.raw)) / s.sample_rate
        np.savetxt(path, np.column_stack([t, s.raw]), delimiter=",", header="t,ax,ay,az",
                   comments="")  # fmt: skip
        paths.append(path)
    Path(f"{tmp}/broken.csv").write_text("t,ax,ay,az\n0,1,2\n")
    return [*paths, f"{tmp}/broken.csv"]


def pages() -> dict[str, str]:
    ck = cj.load_log(cj.mag_demo_log_path())
    with tempfile.TemporaryDirectory() as tmp:
        fleet = list(calibrate_files(fleet_files(tmp), progress=False))
    import pandas as pd

    with pd.option_context("display.max_colwidth", 50):  # Jupyter's default
        frame = to_dataframe(fleet)._repr_html_()
    return {
        "accel": cj.calibrate_accel(cj.demo_log_path())._repr_html_(),
        "mag": cj.calibrate_mag(ck)._repr_html_(),
        "marg": calibrate_marg_log(ck)._repr_html_(),
        "gyro": cj.calibrate_gyro(cj.demo_log_path(), cj.gyro_demo_log_path())._repr_html_(),
        "diagnosis": diagnose_accel(cj.demo_log_path(), progress=False)._repr_html_(),
        "fleet_record": cj.BatchRecord(sensor="accel", entries=fleet)._repr_html_(),
        "fleet_dataframe": frame,
    }


def render(html: Path) -> Path:
    """The page as a PNG, cropped to its content."""
    import pypdfium2
    import weasyprint
    from PIL import ImageOps

    pdf = html.with_suffix(".pdf")
    page = weasyprint.CSS(string="@page { size: 250mm 400mm; margin: 5mm }")
    weasyprint.HTML(str(html)).write_pdf(pdf, stylesheets=[page])
    image = pypdfium2.PdfDocument(pdf)[0].render(scale=1.3).to_pil()
    pdf.unlink()
    bottom = ImageOps.invert(image.convert("L")).getbbox()[3]
    png = html.with_suffix(".png")
    image.crop((0, 0, image.width, min(image.height, bottom + 20))).save(png)
    return png


if __name__ == "__main__":
    OUT.mkdir(exist_ok=True)
    for name, html in pages().items():
        path = OUT / f"{name}.html"
        path.write_text(PAGE.format(html))
        print(render(path))
        path.unlink()
