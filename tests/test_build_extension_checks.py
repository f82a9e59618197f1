"""tools/build_extension.py's own manifest checks: every platform needs one numba and one llvmlite wheel
for each Python of Blender's official builds (4.2-5.0: 3.11; 5.1 and later: 3.13) and for any other
Python it carries wheels for. A platform missing one would install on a Blender of that Python with
no numba, and fail at the first render."""

from __future__ import annotations

import importlib.util
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("_kdp_build_extension", REPO / "tools" / "build_extension.py")
build_extension = sys.modules[_spec.name] = importlib.util.module_from_spec(_spec)  # dataclasses look it up
_spec.loader.exec_module(build_extension)

LINUX = "manylinux_2_27_x86_64.manylinux_2_28_x86_64"


def wheel(dist, python, platform=LINUX):
    version = {"numba": "0.68.1", "llvmlite": "0.50.0"}[dist]
    return f"./wheels/{dist}-{version}-{python}-{python}-{platform}.whl"


def manifest(wheels, platforms=("linux-x64",)):
    return {"platforms": list(platforms), "wheels": wheels}


def errors_of(m):
    try:
        build_extension.check_manifest(m, m["platforms"])
    except build_extension.BuildError as ex:
        return str(ex)
    return ""


def test_the_repository_manifest_serves_python_3_11_and_3_13_everywhere_and_3_14_on_linux():
    m = build_extension.load_manifest(REPO / "blender_manifest.toml")
    wheels = build_extension.check_manifest(m, m["platforms"])  # raises on any problem
    for platform in m["platforms"]:
        mine = [w for w in wheels if platform in w.platforms]
        expected = ["3.11", "3.13", "3.14"] if platform == "linux-x64" else ["3.11", "3.13"]
        assert build_extension.python_versions(mine) == expected, platform


def test_an_extra_python_on_one_platform_must_be_complete():
    both = [wheel(d, py) for d in ("numba", "llvmlite") for py in ("cp311", "cp313")]
    assert errors_of(manifest(both + [wheel("numba", "cp314"), wheel("llvmlite", "cp314")])) == ""
    message = errors_of(manifest(both + [wheel("numba", "cp314")]))
    assert "platform linux-x64 needs exactly one llvmlite wheel for Python 3.14, found none" in message


def test_both_pythons_on_one_platform_pass():
    m = manifest([wheel(d, py) for d in ("numba", "llvmlite") for py in ("cp311", "cp313")])
    assert errors_of(m) == ""


def test_a_platform_missing_one_pythons_wheel_is_named():
    m = manifest([wheel("numba", "cp311"), wheel("llvmlite", "cp311"), wheel("numba", "cp313")])
    message = errors_of(m)
    assert "platform linux-x64 needs exactly one llvmlite wheel for Python 3.13, found none" in message
    assert "3.11" not in message.split("found")[0]


def test_a_platform_missing_an_official_blender_python_is_named():
    mac = "macosx_12_0_arm64"
    m = manifest([wheel(d, py) for d in ("numba", "llvmlite") for py in ("cp311", "cp313")]
                 + [wheel(d, "cp311", mac) for d in ("numba", "llvmlite")], platforms=("linux-x64", "macos-arm64"))
    message = errors_of(m)
    assert "platform macos-arm64 needs exactly one numba wheel for Python 3.13, found none" in message
    assert "platform macos-arm64 needs exactly one llvmlite wheel for Python 3.13, found none" in message
    assert "linux-x64" not in message


def test_two_wheels_of_one_python_are_named():
    m = manifest([wheel("numba", "cp311"), wheel("numba", "cp311").replace("0.68.1", "0.68.0"),
                  wheel("llvmlite", "cp311")])
    assert "needs exactly one numba wheel for Python 3.11, found [" in errors_of(m)


@pytest.mark.parametrize("wheels", [[], [wheel("numba", "cp311")]])
def test_no_wheels_or_no_llvmlite_is_named(wheels):
    message = errors_of(manifest(wheels))
    assert "platform linux-x64 needs exactly one llvmlite wheel for Python 3.11, found none" in message
    assert "platform linux-x64 needs exactly one llvmlite wheel for Python 3.13, found none" in message


def test_a_wheel_appears_in_the_cache_only_whole(tmp_path, monkeypatch):
    """Two builds at once (test runs on two Blenders' Pythons, a build beside the tests) share the cache:
    pip writes its file in place, so the other build could have staged a half-written wheel. The
    download goes to a private folder and is renamed into the cache."""
    cache = tmp_path / "cache"
    target = build_extension.parse_wheel(wheel("numba", "cp311"))
    seen_during_download = []

    def fake_download(w, dest):
        (dest / w.filename).write_bytes(b"half")
        seen_during_download.append(sorted(p.name for p in cache.iterdir() if p.is_file()))
        (dest / w.filename).write_bytes(b"whole wheel")

    monkeypatch.setattr(build_extension, "pip_download", fake_download)
    build_extension.fetch_wheels([target], cache)
    assert seen_during_download == [[]]  # nothing under the wheel's name while it was being written
    assert (cache / target.filename).read_bytes() == b"whole wheel"
    assert sorted(p.name for p in cache.iterdir()) == [target.filename]  # the private folder is gone


def plan(platforms=None, pythons=None):
    args = build_extension.parse_args(["--source", str(REPO)] + (["--platforms", platforms] if platforms else [])
                                      + (["--pythons", pythons] if pythons else []))
    return build_extension.plan_build(args)


def test_one_zip_per_platform_and_python():
    """Each zip carries one Python's numba and llvmlite: Linux 3.11, 3.13 and 3.14, the others 3.11 and 3.13."""
    assert plan("linux-x64").zips == [("linux-x64", "3.11"), ("linux-x64", "3.13"), ("linux-x64", "3.14")]
    assert sorted(plan().zips) == sorted([("linux-x64", "3.11"), ("linux-x64", "3.13"), ("linux-x64", "3.14"),
                                          ("windows-x64", "3.11"), ("windows-x64", "3.13"),
                                          ("macos-arm64", "3.11"), ("macos-arm64", "3.13")])
    only = plan("linux-x64,windows-x64", "3.13")
    assert only.zips == [("linux-x64", "3.13"), ("windows-x64", "3.13")]
    assert sorted(w.filename.split("-")[0] for w in only.wheels) == ["llvmlite", "llvmlite", "numba", "numba"]
    assert {w.python_version for w in only.wheels} == {"3.13"}


def test_a_python_no_blender_bundles_is_refused():
    with pytest.raises(build_extension.BuildError, match="no Blender bundles Python 3.12"):
        plan("linux-x64", "3.12")


def test_each_zip_names_the_blender_versions_of_its_python():
    """4.2 up to (not including) 5.1 bundle 3.11; 5.1 and later 3.13: the ranges meet without a gap."""
    text = (REPO / "blender_manifest.toml").read_text()
    py311 = tomllib.loads(build_extension.versions_text(text, "3.11"))
    py313 = tomllib.loads(build_extension.versions_text(text, "3.13"))
    assert (py311["blender_version_min"], py311["blender_version_max"]) == ("4.2.0", "5.1.0")
    assert py313["blender_version_min"] == py311["blender_version_max"] and "blender_version_max" not in py313
    assert py311["wheels"] == tomllib.loads(text)["wheels"]  # nothing else changes


def test_a_zips_manifest_says_what_it_is_for_without_the_repositorys_comments():
    """The repository manifest's comments speak of every zip's wheels (3.13, 3.14): a py311 zip's would
    mislead. Its fields are the subset's, its one comment names the platform and Python."""
    text = (REPO / "blender_manifest.toml").read_text()
    wheels = [build_extension.parse_wheel(path) for path in tomllib.loads(text)["wheels"]]
    chosen = build_extension.wheels_for_platforms([w for w in wheels if w.python_version == "3.11"], ["linux-x64"])
    staged = build_extension.subset_manifest_text(text, ["linux-x64"], chosen, "3.11")
    comments = [line for line in staged.splitlines() if line.lstrip().startswith("#")]
    assert comments == ["# KD Preview for linux-x64, Blender's Python 3.11 (made by tools/build_extension.py)"]
    fields = tomllib.loads(staged)
    assert fields["platforms"] == ["linux-x64"] and len(fields["wheels"]) == 2
    assert all("cp311" in path for path in fields["wheels"]) and fields["license"] == ["SPDX:GPL-3.0-or-later"]


def fake_zip(path, wheels, python, versions=None):
    text = build_extension.versions_text((REPO / "blender_manifest.toml").read_text(), versions or python)
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("__init__.py", "")
        zf.writestr("blender_manifest.toml", text)
        for name in wheels:
            zf.writestr(name.lstrip("./"), b"wheel")
    return path


def test_a_zip_with_another_pythons_wheel_or_versions_is_broken(tmp_path):
    good = [wheel("numba", "cp311"), wheel("llvmlite", "cp311")]
    build_extension.check_zip(fake_zip(tmp_path / "good.zip", good, "3.11"), "linux-x64", "3.11")  # passes
    with pytest.raises(build_extension.BuildError, match="another platform or Python: numba-0.68.1-cp313"):
        build_extension.check_zip(fake_zip(tmp_path / "mixed.zip", good + [wheel("numba", "cp313")], "3.11"),
                                  "linux-x64", "3.11")
    with pytest.raises(build_extension.BuildError, match="gives Blender 5.1.0 to None, not 4.2.0 to 5.1.0"):
        build_extension.check_zip(fake_zip(tmp_path / "versions.zip", good, "3.11", versions="3.13"),
                                  "linux-x64", "3.11")
