"""The output-directory check (`rafostrack.io.outdir`), made before any work."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from rafostrack.cli import main

pytestmark = pytest.mark.reliability


def test_output_directory_not_writable(tmp_path, sim_mission_dir):
    """Tests run as root, where chmod does not stop writes: make the parent a regular file."""
    blocker = tmp_path / "afile"
    blocker.write_text("not a directory\n")
    out = blocker / "out"
    result = CliRunner().invoke(main, ["track", str(sim_mission_dir / "sim1.csv"), "--out", str(out), "--no-plots"])
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        f"rafostrack: error: {out}: output directory cannot be created: {blocker} is a file, not a directory; "
        "expected --out to name a writable directory"
    )
    # --out names a regular file itself.
    result = CliRunner().invoke(main, ["track", str(sim_mission_dir / "sim1.csv"), "--out", str(blocker), "--no-plots"])
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        f"rafostrack: error: {blocker}: output directory is a file, not a directory; "
        "expected --out to name a writable directory"
    )
    # A failure only met while writing (the float's own directory is a file): still one line, exit 2.
    out = tmp_path / "out"
    out.mkdir()
    (out / "sim1").write_text("in the way\n")
    result = CliRunner().invoke(main, ["track", str(sim_mission_dir / "sim1.csv"), "--out", str(out), "--no-plots"])
    assert result.exit_code == 2
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
    assert result.stderr.startswith(f"rafostrack: error: cannot write output directory {out}: {out / 'sim1'}")
