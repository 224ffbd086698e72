"""An install starts warm: the wheel carries numba's cache of the service's kernels, and a
copy of the package unpacked elsewhere loads them rather than compiling (issue 13, start-up
on the first run)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from ezcompanion.guidance import _jit
from ezcompanion.guidance._jit import kernel_fingerprint, python_sources, user_cache_dir

ROOT = Path(__file__).resolve().parents[1]

# what the first run after an install does: `ezcompanion compile` builds the service's loop
# (the one-vehicle step, loaded or compiled) and says which; then what numba did
_FIRST_RUN = """
import json, sys
import ezcompanion
from ezcompanion.commands import run_compile
run_compile()
from ezcompanion.guidance.single import step_one
stats = step_one.stats
print(json.dumps({"package": ezcompanion.__file__, "hits": len(stats.cache_hits),
                  "misses": len(stats.cache_misses)}))
"""

# the same, where the package cannot be written: as a user who does not own it sees it, the
# check numba and the package make (a file made and removed there) fails (the tests may run
# as root, who writes anywhere)
_READ_ONLY = """
import tempfile
opened = tempfile.TemporaryFile
def refused(*args, dir=None, **kwargs):
    if dir is not None and str(dir).startswith({site!r}):
        raise PermissionError(13, "Permission denied", str(dir))
    return opened(*args, dir=dir, **kwargs)
tempfile.TemporaryFile = refused
"""


def _compiled_environment() -> dict[str, str]:
    """This environment, compiled (whatever this process runs) and with numba's cache where
    the package puts it."""
    dropped = ("NUMBA_CACHE_DIR", "PYTHONPATH", "EZCOMPANION_JIT", "NUMBA_DISABLE_JIT")
    return {key: value for key, value in os.environ.items() if key not in dropped}


def _index_files(site: Path) -> dict[str, bytes]:
    return {str(p.relative_to(site)): p.read_bytes() for p in site.rglob("*.nbi")}


def _build_wheel(source: Path, env: dict[str, str]) -> tuple[Path, str]:
    """The wheel ``pip wheel`` builds (offline) from a copy of the sources at ``source``,
    whose build directory holds a cache of other sources (pip builds in the tree's
    build/), and what the build said."""
    source.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info")
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy(ROOT / name, source / name)
    for package in ("ezcompanion", "sitl_stub"):
        shutil.copytree(ROOT / package, source / package, ignore=ignore)
    stale = source / "build/lib/ezcompanion/guidance/__pycache__/numba-0123456789abcdef"
    (stale / "guidance").mkdir(parents=True)
    (stale / "guidance" / "single.step_one-1.py311.nbi").write_bytes(b"")
    dist = source.parent / f"{source.name}-dist"
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-v", "--no-build-isolation", "--no-deps",
         "--no-cache-dir", "--wheel-dir", str(dist), str(source)],
        env=env, cwd=source.parent, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    said = built.stdout + built.stderr  # pip -v passes the build's output on stderr
    assert built.returncode == 0, said[-5000:]
    (wheel,) = dist.glob("ezcompanion-*.whl")
    return wheel, said


def test_the_wheel_carries_the_kernels_and_its_first_run_loads_them(tmp_path: Path) -> None:
    """``pip wheel`` (setup.py's build step) compiles the service's kernels into the wheel,
    under the digest of the sources it ships. Unpacked at another path, as pip installs it,
    the first run finds every kernel it needs in that cache: numba loads the one-vehicle
    step, misses nothing, and writes no index. Also the cold and warm halves of
    ``ezcompanion compile``. A cache of other sources left in the build directory does not
    ship."""
    source = tmp_path / "source"
    wheel, said = _build_wheel(source, _compiled_environment())
    assert "compiled into numba's cache" in said, said[-5000:]

    digest = kernel_fingerprint(python_sources(source / "ezcompanion" / "guidance"))
    cache = f"ezcompanion/guidance/__pycache__/numba-{digest}/"
    names = zipfile.ZipFile(wheel).namelist()
    shipped = [n for n in names if n.startswith(cache) and n.endswith(".nbi")]
    assert any("/single.step_one-" in n for n in shipped), names
    assert not [n for n in names if n.endswith(".pyc") or "numba-0123" in n]

    site = tmp_path / "site"  # another path than the one it was compiled at
    zipfile.ZipFile(wheel).extractall(site)
    indexed = _index_files(site)
    env = {**_compiled_environment(), "PYTHONPATH": str(site)}
    first = subprocess.run([sys.executable, "-c", _FIRST_RUN], env=env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=600, check=True)  # fmt: skip
    lines = first.stdout.strip().splitlines()
    seen = json.loads(lines[-1])
    assert Path(seen["package"]).is_relative_to(site)
    assert "already in numba's cache, loaded" in first.stdout, first.stdout
    assert seen["hits"] >= 1 and seen["misses"] == 0, seen
    assert _index_files(site) == indexed  # nothing compiled, nothing re-indexed

    # installed where the running user cannot write (a system-wide install): the first run
    # loads a copy of the shipped cache, made in the user's cache, and still compiles nothing
    users = tmp_path / "user-cache"
    env = {**env, "XDG_CACHE_HOME": str(users)}
    script = _READ_ONLY.format(site=str(site)) + _FIRST_RUN
    read_only = subprocess.run([sys.executable, "-c", script], env=env, cwd=tmp_path,
                               capture_output=True, text=True, timeout=600,
                               check=True)  # fmt: skip
    seen = json.loads(read_only.stdout.strip().splitlines()[-1])
    assert "already in numba's cache, loaded" in read_only.stdout, read_only.stdout
    assert seen["hits"] >= 1 and seen["misses"] == 0, seen
    assert _index_files(site) == indexed
    copied = {p.name: p.read_bytes() for p in users.rglob("*.nbi")}
    assert copied == {Path(name).name: data for name, data in indexed.items()}


def test_a_wheel_built_without_the_compile_carries_no_cache(tmp_path: Path) -> None:
    """``EZCOMPANION_BUILD_COMPILE=0``: nothing compiled, and no cache an earlier build left
    in the build directory ships either."""
    env = {**_compiled_environment(), "EZCOMPANION_BUILD_COMPILE": "0"}
    wheel, said = _build_wheel(tmp_path / "source", env)
    assert "numba's cache" not in said
    names = zipfile.ZipFile(wheel).namelist()
    assert "ezcompanion/guidance/_jit.py" in names
    assert not [n for n in names if "numba-" in n], names


def test_a_read_only_install_seeds_the_users_cache_once(tmp_path: Path) -> None:
    """``_seeded``: the shipped cache copied to the user's where that does not exist yet,
    whole (nothing half-made left beside it); an existing copy kept as it is (another
    process made it, or numba has added to it); with nothing shipped, an empty directory
    for numba to compile into; where the user's cache cannot be made, the shipped path."""
    shipped = tmp_path / "site" / "numba-0123"
    (shipped / "guidance").mkdir(parents=True)
    (shipped / "guidance" / "single.step_one-1.py311.nbi").write_bytes(b"index")
    target = tmp_path / "users" / "ezcompanion" / "numba-0123"
    assert _jit._seeded(target, shipped) == target
    assert (target / "guidance" / "single.step_one-1.py311.nbi").read_bytes() == b"index"
    assert [p.name for p in target.parent.iterdir()] == ["numba-0123"]
    (shipped / "guidance" / "law.evaluate-1.py311.nbi").write_bytes(b"new")
    (target / "guidance" / "single.step_one-1.py311.nbi").write_bytes(b"numba's since")
    assert _jit._seeded(target, shipped) == target
    kept = sorted(p.name for p in (target / "guidance").iterdir())
    assert kept == ["single.step_one-1.py311.nbi"]
    assert (target / "guidance" / "single.step_one-1.py311.nbi").read_bytes() == b"numba's since"
    empty = tmp_path / "users" / "ezcompanion" / "numba-4567"
    assert _jit._seeded(empty, tmp_path / "nothing-shipped") == empty
    assert empty.is_dir() and not list(empty.iterdir())
    (tmp_path / "a-file").write_text("")
    blocked = tmp_path / "a-file" / "ezcompanion" / "numba-0123"
    assert _jit._seeded(blocked, shipped) == shipped
    # an install whose directories and files are read-only: the copy is the user's to write
    for path in (shipped / "guidance" / "law.evaluate-1.py311.nbi", shipped / "guidance", shipped):
        path.chmod(0o555 if path.is_dir() else 0o444)
    frozen = tmp_path / "users" / "ezcompanion" / "numba-89ab"
    assert _jit._seeded(frozen, shipped) == frozen
    for path in (frozen, *frozen.rglob("*")):
        assert path.stat().st_mode & (0o700 if path.is_dir() else 0o600) == (
            0o700 if path.is_dir() else 0o600), (path, oct(path.stat().st_mode))  # fmt: skip
    for path in (shipped, shipped / "guidance"):
        path.chmod(0o755)


def test_stale_caches_beside_the_one_in_use_are_removed(tmp_path: Path) -> None:
    """``prune_caches``: of the other caches beside the one in use, those among the last used
    (``_CACHES_KEPT`` with it) or used within a week stay, the others go; a half-made copy
    goes once an hour old; nothing else is touched, and the one in use is marked used.
    Where the directory cannot be written nothing is tried; a copy just seeded from an
    old shipped cache is not taken for a stale one."""
    now = 1_900_000_000.0
    hour = 3600.0

    def made(name: str, age_s: float) -> Path:
        path = tmp_path / name
        (path / "guidance").mkdir(parents=True)
        os.utime(path, (now - age_s, now - age_s))
        return path

    current = made("numba-" + "0" * 16, 9 * 24 * hour)
    ages = {"1": hour, "2": 2 * hour, "3": 150 * hour, "4": 170 * hour, "5": 200 * hour}
    others = {key: made("numba-" + key * 16, age) for key, age in ages.items()}
    old_partial = made(".numba-" + "0" * 16 + "-abc", 2 * hour)
    new_partial = made(".numba-" + "0" * 16 + "-def", 0.1 * hour)
    unrelated = [made("numba-elsewhere", 900 * hour), made(".numba-elsewhere", 900 * hour),
                 made("other", 900 * hour)]  # fmt: skip
    (tmp_path / "law.cpython-311.pyc").write_bytes(b"")
    os.utime(tmp_path / "law.cpython-311.pyc", (now - 90 * hour, now - 90 * hour))
    removed = _jit.prune_caches(current, now)
    assert sorted(removed) == sorted([others["4"], others["5"], old_partial])
    # kept: the two used last with the one in use, and the third as it was used within a week
    for path in (current, others["1"], others["2"], others["3"], new_partial, *unrelated):
        assert path.is_dir(), path
    assert (tmp_path / "law.cpython-311.pyc").exists()
    assert current.stat().st_mtime == now
    assert _jit.prune_caches(tmp_path / "nowhere" / current.name, now) == []
    # a directory this user cannot write to: nothing is tried (the test runs as root, to
    # whom every mode is writable: the check is made as the code makes it)
    stale = made("numba-" + "6" * 16, 900 * hour)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_jit.os, "access", lambda path, mode: False)
        assert _jit.prune_caches(current, now) == [] and stale.is_dir()
    # a copy seeded from a shipped cache months old is new, not stale
    shipped = made("shipped", 0.0)
    months_ago = time.time() - 90 * 24 * hour
    os.utime(shipped, (months_ago, months_ago))
    seeded = _jit._seeded(tmp_path / "users" / ("numba-" + "7" * 16), shipped)
    assert seeded.parent.name == "users" and time.time() - seeded.stat().st_mtime < 600


def test_importing_the_package_prunes_its_caches(tmp_path: Path) -> None:
    """The stale cache of an earlier edit under ``NUMBA_CACHE_DIR`` goes when the package is
    imported, and the one in use is kept (``prune_caches``, called where the cache
    directory is set)."""
    stale = tmp_path / ("numba-" + "f" * 16)
    (stale / "guidance").mkdir(parents=True)
    os.utime(stale, (1e9, 1e9))
    for key in "abc":  # used last, but not within a week: the two newest stay
        (tmp_path / ("numba-" + key * 16)).mkdir()
        used = time.time() - 9 * 86400.0 + ord(key)
        os.utime(tmp_path / ("numba-" + key * 16), (used, used))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "EZCOMPANION_JIT": "1"}
    done = subprocess.run(
        [sys.executable, "-c", "import ezcompanion.guidance._jit as j, numba; "
         "print(numba.config.CACHE_DIR)"],
        env=env, capture_output=True, text=True, check=True, timeout=120,
    )  # fmt: skip
    in_use = Path(done.stdout.strip())
    assert in_use.parent == tmp_path and in_use.name == Path(_jit.cache_dir("")).name
    kept = sorted(p.name for p in tmp_path.iterdir() if p != in_use)
    assert kept == ["numba-" + "b" * 16, "numba-" + "c" * 16]


def test_with_no_home_a_read_only_install_starts_as_before(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the package cannot be written: the cache is the user's copy under
    ``$XDG_CACHE_HOME``; with neither that nor a home directory to be found (no HOME, no
    passwd entry: ``Path.home`` raises), the shipped path, where numba finds its own place
    and compiles, as before; never an error at import."""
    monkeypatch.setattr(_jit, "_writable", lambda directory: False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    name = Path(_jit.cache_dir("")).name
    assert _jit.cache_dir("") == str(tmp_path / "cache" / "ezcompanion" / name)
    assert (tmp_path / "cache" / "ezcompanion" / name).is_dir()
    assert user_cache_dir() == tmp_path / "cache" / "ezcompanion"
    monkeypatch.delenv("XDG_CACHE_HOME")

    def no_home() -> Path:
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", no_home)
    assert _jit.cache_dir("") == str(_jit._HERE / "__pycache__" / name)
