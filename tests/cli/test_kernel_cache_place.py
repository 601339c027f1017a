"""Where the compiled kernels are cached (sphere_cli/__init__.py): the user's cache directory,
else a directory of this user's own in the temporary directory, said in each run's log. With a
read-only home and a read-only install (a container, a cluster's compute node) Numba found no
place at all and every command failed at import with a traceback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cli_test_support import TINY

from sphere_cli import api

PLACE = "import json, numba, sphere_cli as s;print(json.dumps([numba.config.CACHE_DIR, s.KERNEL_CACHE_NOTE]))"


def _place(tmp_path: Path, cache_home: Path) -> tuple[str, str | None]:
    """numba's cache directory and the note, in a fresh process whose cache home is `cache_home`
    and whose temporary directory is tmp_path / "tmp"."""
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env |= {"XDG_CACHE_HOME": str(cache_home), "TMPDIR": str(tmp_path / "tmp")}
    (tmp_path / "tmp").mkdir(exist_ok=True)
    command = [sys.executable, "-c", PLACE]
    done = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return tuple(json.loads(done.stdout))


def test_the_kernels_are_cached_in_the_users_cache_directory(tmp_path):
    place, note = _place(tmp_path, tmp_path / "cache")
    assert Path(place).parent == tmp_path / "cache" / "sphere" / "numba" and note is None


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="POSIX only")
def test_an_unwritable_cache_home_sends_the_kernels_to_a_temporary_directory_of_this_users_own(tmp_path):
    (tmp_path / "file").write_text("")  # a home below which nothing can be made, even by root
    place, note = _place(tmp_path, tmp_path / "file" / "cache")
    own = tmp_path / "tmp" / f"sphere-{os.getuid()}"
    assert Path(place).parent == own / "numba"
    assert own.stat().st_mode & 0o777 == 0o700
    assert note == (
        f"{tmp_path / 'file' / 'cache'} cannot be written: the compiled kernels are cached in {place}, "
        "which may not last; set NUMBA_CACHE_DIR to a directory that does"
    )


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="POSIX only")
def test_a_temporary_directory_others_can_write_to_is_not_used(tmp_path):
    own = tmp_path / "tmp" / f"sphere-{os.getuid()}"
    own.mkdir(parents=True)
    own.chmod(0o777)  # anyone could plant kernels there, which Numba loads as pickles
    (tmp_path / "file").write_text("")
    place, note = _place(tmp_path, tmp_path / "file" / "cache")
    assert not str(place).startswith(str(own)) and note is None


def test_a_run_says_in_its_log_where_its_kernels_are_cached_when_not_in_the_users_cache(
    tmp_path, monkeypatch, capsys
):
    (tmp_path / "case.toml").write_text(TINY)
    note = "/home/u/.cache cannot be written: the compiled kernels are cached in /tmp/sphere-1/numba/x"
    monkeypatch.setattr(api, "KERNEL_CACHE_NOTE", note)
    api.run(tmp_path / "case.toml", tmp_path / "run")
    assert f"WARNING {note}" in (tmp_path / "run" / "run.log").read_text()
    assert f"sphere: warning: {note}" in capsys.readouterr().err
