"""The output-directory check (`rafostrack.io.outdir`), made before any work."""

from __future__ import annotations

import os

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


def test_a_killed_runs_staging_is_removed_and_a_live_ones_kept(tmp_path):
    """`remove_stale_siblings`: a staging or trash sibling whose process is gone is removed
    (a `track` killed mid-write left it); one of a running process is not."""
    import subprocess
    import sys

    from rafostrack.io.outdir import remove_stale_siblings

    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(done.stdout)
    final = tmp_path / "float759"
    stale = [tmp_path / f".float759.tmp-{dead}", tmp_path / f".float759.trash-{dead}"]
    live = tmp_path / f".float759.tmp-{os.getppid()}"
    other = tmp_path / f".float767.tmp-{dead}"
    for path in [*stale, live, other]:
        path.mkdir()
        (path / "track.parquet").write_bytes(b"partial")
    assert sorted(remove_stale_siblings(final)) == sorted(stale)
    assert live.exists() and other.exists() and not any(p.exists() for p in stale)
