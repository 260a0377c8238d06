"""Every Python block of README.md and docs/**/*.md runs as written (issue 13: the README's
own examples raised). The blocks of one file run in order in one namespace, as a reader would
paste them into one notebook, in a temporary working directory (they write files)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks(path: Path) -> list[str]:
    return _BLOCK.findall(path.read_text())


def test_the_readme_has_python_examples():
    # guards the extraction itself: a changed fence style must not silently run nothing
    assert len(python_blocks(ROOT / "README.md")) >= 3
    assert all(python_blocks(ROOT / "docs" / p) for p in ("pipeline.md", "batches.md"))


@pytest.mark.parametrize(
    "path", [p for p in DOCS if python_blocks(p)], ids=lambda p: str(p.relative_to(ROOT))
)
def test_python_blocks_run_as_written(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    for i, block in enumerate(python_blocks(path)):
        code = compile(block, f"{path.name}[python block {i + 1}]", "exec")
        exec(code, namespace)  # noqa: S102 - the documentation's own examples


_COMMAND = re.compile(r"`(calib-jax [^`]+)`")


def readme_commands() -> list[str]:
    """The commands of the README's 'One example per task' table, in order."""
    text = (ROOT / "README.md").read_text()
    table = text[text.index("## One example per task") :]
    table = table[: table.index("\n\n", table.index("|---"))]
    return _COMMAND.findall(table)


def test_readme_commands_run_as_written(tmp_path, monkeypatch, capsys):
    """Each command of the README's task table runs as written, with its placeholders (the
    reader's own files) filled with logs shipped in the package: ``log.csv`` is the Xsens
    recording written as CSV for accel and diagnose, the CK-Explorer tumble for mag and marg;
    ``log.csv`` for gyro is the Xsens accelerometer and gyro pair as one CSV; ``logs/`` holds
    both CSV copies of the Xsens log; the serial port is a simulated board
    (48 poses at 20x speed), so ``record`` stops on its own when the 48 poses are covered.
    ``apply`` and ``export`` use the calibration the accel row wrote. Exit 0 and the files
    each command says it writes."""
    import shutil

    import numpy as np

    import calib_jax as cj
    from calib_jax.cli import main
    from calib_jax.io.sim_device import spawn

    commands = readme_commands()
    verbs = [c.split()[1] for c in commands]
    assert verbs == [
        "accel", "mag", "marg", "gyro", "diagnose", "batch", "record", "apply", "export"
    ]  # fmt: skip
    xsens = cj.load_log(cj.demo_log_path())
    xsens_csv = tmp_path / "xsens.csv"
    rows = np.column_stack([xsens.t, xsens.acc])
    np.savetxt(xsens_csv, rows, delimiter=",", header="t,ax,ay,az", comments="", fmt="%.9g")
    gyro = cj.load_log(cj.gyro_demo_log_path(), sensor="gyro").gyro
    imu_csv = tmp_path / "xsens_imu.csv"
    rows = np.column_stack([xsens.t, xsens.acc, gyro])
    np.savetxt(imu_csv, rows, delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.9g")
    logs = {"accel": xsens_csv, "diagnose": xsens_csv, "apply": xsens_csv, "gyro": imu_csv}
    logs |= {"mag": cj.mag_demo_log_path(), "marg": cj.mag_demo_log_path()}
    work = tmp_path / "work"
    (work / "logs").mkdir(parents=True)
    for k in range(2):
        shutil.copy(xsens_csv, work / "logs" / f"board{k}.csv")
    board = spawn(tmp_path / "imu0", poses=48, hold=1.0, move=0.5, speed=20, header=True)
    monkeypatch.chdir(work)
    try:
        for command, verb in zip(commands, verbs, strict=True):
            argv = command.replace("/dev/ttyUSB0", str(tmp_path / "imu0")).split()[1:]
            if verb in logs:
                shutil.copy(logs[verb], work / "log.csv")
                shutil.copy(logs[verb], work / "new.csv")
            assert main(argv) == 0, (command, capsys.readouterr())
    finally:
        board.kill()
        board.wait()
    names = ("cal.json", "cal.png", "gyro.json", "all.json", "all.csv", "imu.csv")
    for name in (*names, "imu.calib.json"):
        assert (work / name).stat().st_size > 0, name
    assert any((work / "figures").iterdir())
    assert cj.BatchRecord.load(work / "all.json").statuses == ["ok", "ok"]
    out = capsys.readouterr().out
    assert "const" in out or "float" in out  # export --format c printed a C header
