#!/usr/bin/env python3
"""Build the KD Preview extension zips, one per platform and Blender Python, with numba and llvmlite
bundled for that Python only (a zip with every Python's wheels was three times as large).

Steps:
  1. download the numba and llvmlite wheels that ``blender_manifest.toml`` lists
     (only for the chosen platforms and Pythons) into a cache folder, skipping files already there;
  2. for each platform and Python: copy the repository (minus what the manifest's ``[build]
     paths_exclude_pattern`` leaves out) into a staging folder, put that Python's wheels under its
     ``wheels/`` and limit its manifest to them, with the Blender versions that bundle that Python
     (``blender_version_min`` / ``blender_version_max``, BLENDER_RANGES), so Blender refuses a zip
     made for another Python;
  3. validate the staged manifest strictly with Blender's own ``blender_ext.py validate`` (shipped in
     the ``bpy`` module) plus our own checks (every wheel exists, each platform has numba AND llvmlite
     for every official Blender Python);
  4. build the zip with ``blender_ext.py build``, what ``blender --command extension build`` runs;
  5. open every zip and fail unless it holds exactly its platform's and Python's numba and llvmlite
     wheels and its manifest's Blender versions.

Usage: python tools/build_extension.py [--platforms linux-x64,windows-x64] [--pythons 3.11] [--out dist]
Needs only the standard library, pip, and the ``bpy`` module installed (for blender_ext.py).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from dataclasses import dataclass
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
MANIFEST = "blender_manifest.toml"
REQUIRED_DISTS = ("numba", "llvmlite")
# The Pythons of Blender's official builds: 4.2 to 5.0 bundle 3.11, 5.1 and later 3.13. Every platform
# needs wheels for both; a platform may carry more (linux-x64: 3.14, which Linux distributions' own
# Blender packages use, Debian's 5.2.2 among them).
BLENDER_PYTHONS = ("3.11", "3.13")
# The Blender versions of each Python's zip: [min, max), as the manifest's fields mean them (max: the
# first version not supported; None: no upper bound). 3.14 is Linux distributions' Python for Blender
# 5.1 and later (Debian's 5.2.2); its zip overlaps the 3.13 one and is told apart by its name.
BLENDER_RANGES = {"3.11": ("4.2.0", "5.1.0"), "3.13": ("5.1.0", None), "3.14": ("5.1.0", None)}
FORBIDDEN_DISTS = ("numpy",)  # Blender ships its own numpy; bundling one breaks bpy.
REQUIRED_ZIP_FILES = ("__init__.py", MANIFEST)
OS_PREFIXES = (("manylinux", "linux"), ("musllinux", "linux"), ("linux", "linux"),
               ("macosx", "macos"), ("win", "windows"))
ARCHES = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64", "arm64": "arm64"}
# What blender_ext.py leaves out when the manifest has no `paths_exclude_pattern`.
DEFAULT_EXCLUDES = ["__pycache__/", ".*", "/*.zip", "*.blend[1-9]"]


class BuildError(Exception):
    """A build step failed; the message says why."""


@dataclass(frozen=True)
class Wheel:
    """One wheel listed in the manifest, parsed from its file name."""

    path: str  # As written in the manifest, e.g. "./wheels/numba-....whl".
    dist: str
    version: str
    python_tag: str
    abi_tag: str
    platform_tag: str  # May be compound: "manylinux_2_27_x86_64.manylinux_2_28_x86_64".

    @property
    def filename(self) -> str:
        """The wheel's file name."""
        return os.path.basename(self.path)

    @property
    def platforms(self) -> set[str]:
        """The Blender platforms ("linux-x64", ...) this wheel installs on."""
        result: set[str] = set()
        for tag in self.platform_tag.split("."):
            result |= blender_platforms_from_tag(tag)
        return result

    @property
    def python_version(self) -> str:
        """The "3.11"-style Python version of a "cp311" tag."""
        digits = self.python_tag.lstrip("cpy")
        return "{}.{}".format(digits[0], digits[1:])


def blender_platforms_from_tag(tag: str) -> set[str]:
    """Map one wheel platform tag ("win_amd64", "macosx_12_0_arm64") to Blender platforms."""
    if tag == "any":
        return {"any"}
    os_name = next((blender for prefix, blender in OS_PREFIXES if tag.startswith(prefix)), None)
    if os_name is None:
        return set()
    if tag.endswith("universal2"):
        return {"macos-x64", "macos-arm64"}
    arch = next((ARCHES[a] for a in ARCHES if tag.endswith("_" + a)), None)
    return {"{}-{}".format(os_name, arch)} if arch else set()


def parse_wheel(path: str) -> Wheel:
    """Parse a manifest wheel path; raise BuildError if the name does not follow the wheel spec."""
    parts = os.path.basename(path)[:-len(".whl")].split("-")
    if not path.endswith(".whl") or len(parts) not in (5, 6):
        raise BuildError("not a wheel file name: {!r}".format(path))
    return Wheel(path, parts[0].lower().replace("_", "-"), parts[1], parts[-3], parts[-2], parts[-1])


def load_manifest(path: Path) -> dict:
    """Read a blender_manifest.toml."""
    with open(path, "rb") as fh:
        return tomllib.load(fh)


# -----------------------------------------------------------------------------
# Locating Blender's extension CLI inside the bpy module.

def find_blender_ext() -> Path:
    """Return the path of blender_ext.py inside the installed bpy module (without importing bpy)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise BuildError("the 'bpy' module is not installed in {} (pip install bpy)".format(sys.executable))
    for location in spec.submodule_search_locations:
        found = sorted(Path(location).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if found:
            return found[-1]
    raise BuildError("blender_ext.py not found inside the bpy module")


def find_valid_tags(blender_ext: Path) -> Path:
    """Return Blender's own tag list, which `blender --command extension` validates tags against."""
    scripts = blender_ext.parents[3]
    return scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"


def load_path_matcher(blender_ext: Path, patterns: list[str]):
    """Return blender_ext's gitignore-style PathPatternMatch for these patterns."""
    spec = importlib.util.spec_from_file_location("_kdp_blender_ext", blender_ext)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.PathPatternMatch(patterns)


def run_blender_ext(blender_ext: Path, args: list[str]) -> str:
    """Run blender_ext.py with args; return its output or raise BuildError with it."""
    cmd = [sys.executable, str(blender_ext), *args]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    output = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0:
        raise BuildError("blender_ext.py {} failed (exit {}):\n{}".format(args[0], proc.returncode, output))
    return output


# -----------------------------------------------------------------------------
# Step 1: download the wheels.

def wheels_for_platforms(wheels: list[Wheel], platforms: list[str]) -> list[Wheel]:
    """Return the wheels that install on at least one of the platforms."""
    return [w for w in wheels if w.platforms & (set(platforms) | {"any"})]


def pip_download(wheel: Wheel, cache: Path) -> None:
    """Download exactly this wheel into cache with pip, for its own platform tags."""
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
           "--disable-pip-version-check", "--quiet", "--dest", str(cache),
           "--python-version", wheel.python_version, "--implementation", "cp", "--abi", wheel.abi_tag]
    for tag in wheel.platform_tag.split("."):
        cmd += ["--platform", tag]
    cmd.append("{}=={}".format(wheel.dist, wheel.version))
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise BuildError("pip could not download {}:\n{}".format(wheel.filename, proc.stderr.strip()))


def fetch_wheels(wheels: list[Wheel], cache: Path) -> None:
    """Make sure every wheel is in the cache, downloading the missing ones. Each is downloaded into a
    private temporary folder and renamed into the cache, so a build running at the same time (a test
    run on another Blender's Python, or a user's build beside the tests) sees a wheel whole or not at
    all: pip writes its file in place, and the other build could stage a half-written wheel."""
    cache.mkdir(parents=True, exist_ok=True)
    for wheel in wheels:
        if (cache / wheel.filename).is_file():
            print("cached:     {}".format(wheel.filename))
            continue
        print("downloading {} ...".format(wheel.filename), flush=True)
        with tempfile.TemporaryDirectory(dir=cache, prefix=".download-") as private:
            downloaded = Path(private) / wheel.filename
            pip_download(wheel, downloaded.parent)
            if not downloaded.is_file():
                raise BuildError("pip saved a different file than the manifest lists ({}): fix the manifest's "
                                 "wheel names, see {}".format(wheel.filename, sorted(os.listdir(private))))
            os.replace(downloaded, cache / wheel.filename)


# -----------------------------------------------------------------------------
# Step 2: stage a copy of the repo with the wheels.

def copy_tree(source: Path, stage: Path, matcher, skip: set[Path]) -> None:
    """Copy source into stage, skipping what the build would exclude anyway and the `skip` folders."""
    for dirpath, dirnames, filenames in os.walk(source):
        rel_dir = os.path.relpath(dirpath, source).replace(os.sep, "/")
        prefix = "" if rel_dir == "." else rel_dir + "/"
        dirnames[:] = [d for d in dirnames if not matcher.test_path(prefix + d + "/")
                       and Path(dirpath, d).resolve() not in skip]
        for name in filenames:
            if not matcher.test_path(prefix + name):
                target = stage / prefix / name
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(os.path.join(dirpath, name), target)


def subset_manifest_text(text: str, platforms: list[str], wheels: list[Wheel], python: str | None = None) -> str:
    """Rewrite the top-level `platforms` and `wheels` arrays to list only the chosen ones; with `python`,
    set `blender_version_min` (and `blender_version_max`, when bounded) to its BLENDER_RANGES entry."""
    def replace(key: str, values: list[str], text: str) -> str:
        body = ", ".join('"{}"'.format(v) for v in values)
        new, count = re.subn(r"(?ms)^{}\s*=\s*\[.*?\]".format(key), "{} = [{}]".format(key, body), text, count=1)
        if count != 1:
            raise BuildError("could not find the `{} = [...]` array in the manifest".format(key))
        return new
    text = replace("platforms", platforms, text)
    text = replace("wheels", [w.path for w in wheels], text)
    if python is None:
        return text
    return _zip_comments(versions_text(text, python), platforms, python)


def _zip_comments(text: str, platforms: list[str], python: str) -> str:
    """A zip's manifest without the repository manifest's comments (they speak of every zip's wheels),
    headed by what this zip is for."""
    kept = [line for line in text.splitlines() if not line.lstrip().startswith("#")]
    header = "# KD Preview for {}, Blender's Python {} (made by tools/build_extension.py)".format(
        ", ".join(platforms), python)
    return "\n".join([header] + kept) + "\n"


def versions_text(text: str, python: str) -> str:
    """The manifest text with the Blender versions whose bundled Python is `python`."""
    low, high = BLENDER_RANGES[python]
    fields = 'blender_version_min = "{}"'.format(low) + ('\nblender_version_max = "{}"'.format(high) if high else "")
    text = re.sub(r"(?m)^blender_version_max\s*=.*\n?", "", text)
    new, count = re.subn(r"(?m)^blender_version_min\s*=.*$", fields, text, count=1)
    if count != 1:
        raise BuildError("could not find `blender_version_min = ...` in the manifest")
    return new


def stage_source(source: Path, stage: Path, cache: Path, platforms: list[str],
                 wheels: list[Wheel], matcher, skip: set[Path], python: str | None = None) -> None:
    """Fill stage with the repo files, the chosen wheels and a manifest limited to the chosen platforms
    (and, with `python`, to the Blender versions that bundle it)."""
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)
    copy_tree(source, stage, matcher, skip | {stage})
    for wheel in wheels:
        target = stage / wheel.path
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cache / wheel.filename, target)
    text = (source / MANIFEST).read_text(encoding="utf-8")
    (stage / MANIFEST).write_text(subset_manifest_text(text, platforms, wheels, python), encoding="utf-8")
    staged = load_manifest(stage / MANIFEST)
    if staged.get("platforms") != platforms or staged.get("wheels") != [w.path for w in wheels]:
        raise BuildError("the staged manifest's platforms/wheels came out wrong: {} {}".format(
            staged.get("platforms"), staged.get("wheels")))


# -----------------------------------------------------------------------------
# Step 3: validate.

def check_manifest(manifest: dict, platforms: list[str]) -> list[Wheel]:
    """Our own manifest checks; return the parsed wheels. Raise BuildError listing every problem."""
    errors = []
    declared = manifest.get("platforms") or []
    wheels = [parse_wheel(p) for p in manifest.get("wheels") or []]
    errors += ["platform {} is not in the manifest's platforms {}".format(p, declared)
               for p in platforms if p not in declared]
    errors += ["{} must not be bundled (Blender ships its own)".format(w.filename)
               for w in wheels if w.dist in FORBIDDEN_DISTS]
    errors += ["{} installs on no known platform".format(w.filename) for w in wheels if not w.platforms]
    for platform in declared:
        errors += platform_wheel_errors(platform, [w.path for w in wheels])
    if errors:
        raise BuildError("manifest check failed:\n  " + "\n  ".join(errors))
    return wheels


def python_versions(wheels: list[Wheel]) -> list[str]:
    """The Python versions ("3.11", ...) the wheels are built for."""
    return sorted({w.python_version for w in wheels})


def platform_wheel_errors(platform: str, filenames: list[str]) -> list[str]:
    """Errors for a platform unless, for each official Blender Python (BLENDER_PYTHONS) and any other
    Python it has wheels for, exactly one wheel of each required distribution installs on it (Blender
    installs the wheels matching its own platform and Python)."""
    errors = []
    wheels = [w for w in map(parse_wheel, filenames) if platform in w.platforms]
    for version in sorted(set(BLENDER_PYTHONS) | set(python_versions(wheels))):
        for dist in REQUIRED_DISTS:
            found = [w.filename for w in wheels if w.dist == dist and w.python_version == version]
            if len(found) != 1:
                errors.append("platform {} needs exactly one {} wheel for Python {}, found {}".format(
                    platform, dist, version, found or "none"))
    return errors


def check_staged_files(stage: Path, wheels: list[Wheel]) -> None:
    """The staged add-on needs its root __init__.py and every wheel its manifest lists."""
    missing = [w.path for w in wheels if not (stage / w.path).is_file()]
    errors = ["wheels listed in the manifest are missing: {}".format(missing)] if missing else []
    if not (stage / "__init__.py").is_file():
        errors.append("the add-on's root __init__.py is missing (Blender requires one next to {})".format(MANIFEST))
    if errors:
        raise BuildError("staged files check failed:\n  " + "\n  ".join(errors))


# -----------------------------------------------------------------------------
# Steps 4 and 5: build, then check each zip.

def zip_name(manifest: dict, platform: str, python: str) -> str:
    """A zip's file name: the name `build --split-platforms` gives a platform's zip, with its Python
    ("kd_preview-0.1.0-linux_x64-py311.zip")."""
    return "{}-{}-{}-py{}.zip".format(manifest["id"], manifest["version"], platform.replace("-", "_"),
                                      python.replace(".", ""))


def check_zip(path: Path, platform: str, python: str) -> None:
    """Fail unless the zip holds the add-on files, exactly one numba and one llvmlite wheel, both for
    its platform and Python, and a manifest with that Python's Blender versions."""
    if not path.is_file():
        raise BuildError("expected zip was not built: {}".format(path))
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        manifest = tomllib.loads(zf.read(MANIFEST).decode("utf-8")) if MANIFEST in names else {}
    missing = [f for f in REQUIRED_ZIP_FILES if f not in names]
    wheels = [parse_wheel(os.path.basename(n)) for n in names if n.endswith(".whl")]
    errors = ["missing {}".format(f) for f in missing]
    errors += ["holds a wheel for another platform or Python: {}".format(w.filename) for w in wheels
               if platform not in w.platforms | {"any"} or w.python_version != python]
    for dist in REQUIRED_DISTS:
        found = [w.filename for w in wheels if w.dist == dist]
        if len(found) != 1:
            errors.append("needs exactly one {} wheel, found {}".format(dist, found or "none"))
    low, high = BLENDER_RANGES[python]
    if (manifest.get("blender_version_min"), manifest.get("blender_version_max")) != (low, high):
        errors.append("its manifest gives Blender {} to {}, not {} to {} (Python {})".format(
            manifest.get("blender_version_min"), manifest.get("blender_version_max"), low, high, python))
    if errors:
        raise BuildError("{} is broken:\n  {}".format(path.name, "\n  ".join(errors)))


@dataclass(frozen=True)
class Plan:
    """What one build makes: the manifest, the zips' (platform, Python) pairs and their wheels."""

    manifest: dict
    zips: list[tuple[str, str]]
    wheels: list[Wheel]


def plan_build(args: argparse.Namespace) -> Plan:
    """Check the manifest and pick the (platform, Python) zips to build (--platforms, --pythons)."""
    source = Path(args.source).resolve()
    if not (source / MANIFEST).is_file():
        raise BuildError("no {} in {}".format(MANIFEST, source))
    manifest = load_manifest(source / MANIFEST)
    platforms = parse_platforms(args.platforms, manifest)
    wheels = wheels_for_platforms(check_manifest(manifest, platforms), platforms)
    wanted = [p.strip() for p in (args.pythons or "").split(",") if p.strip()]
    unknown = [p for p in wanted if p not in BLENDER_RANGES]
    if unknown:
        raise BuildError("--pythons: no Blender bundles Python {} (known: {})".format(
            ", ".join(unknown), ", ".join(BLENDER_RANGES)))
    zips = [(platform, python) for platform in platforms
            for python in python_versions([w for w in wheels if platform in w.platforms])
            if not wanted or python in wanted]
    if not zips:
        raise BuildError("no zip to build: no wheels for Python {} on {}".format(", ".join(wanted), ", ".join(platforms)))
    return Plan(manifest, zips, [w for w in wheels if any(w.python_version == py and pl in w.platforms
                                                              for pl, py in zips)])


def build_zip(args: argparse.Namespace, plan: Plan, platform: str, python: str, blender_ext: Path,
              tags: Path) -> Path:
    """Steps 2 to 5 for one platform and Python: stage, validate, build, check; return the zip."""
    source, cache, out = Path(args.source).resolve(), Path(args.cache).resolve(), Path(args.out).resolve()
    wheels = [w for w in plan.wheels if platform in w.platforms and w.python_version == python]
    patterns = plan.manifest.get("build", {}).get("paths_exclude_pattern") or DEFAULT_EXCLUDES
    stage = Path(args.stage).resolve() / plan.manifest["id"]
    stage_source(source, stage, cache, [platform], wheels, load_path_matcher(blender_ext, patterns),
                 skip={cache, out}, python=python)
    check_staged_files(stage, wheels)
    run_blender_ext(blender_ext, ["validate", "--valid-tags", str(tags), str(stage)])
    out.mkdir(parents=True, exist_ok=True)  # blender_ext.py does not create it.
    path = out / zip_name(plan.manifest, platform, python)
    run_blender_ext(blender_ext, ["build", "--source-dir", str(stage), "--output-filepath", str(path),
                                  "--valid-tags", str(tags)])
    check_zip(path, platform, python)
    run_blender_ext(blender_ext, ["validate", "--valid-tags", str(tags), str(path)])
    return path


def build(args: argparse.Namespace) -> list[Path]:
    """Run all the steps; return the built zips."""
    blender_ext = find_blender_ext()
    tags = find_valid_tags(blender_ext)
    plan = plan_build(args)
    fetch_wheels(plan.wheels, Path(args.cache).resolve())
    return [build_zip(args, plan, platform, python, blender_ext, tags) for platform, python in plan.zips]


def parse_platforms(text: str | None, manifest: dict) -> list[str]:
    """The platforms to build: the --platforms list, or all the manifest declares."""
    chosen = [p.strip() for p in (text or "").split(",") if p.strip()] or list(manifest.get("platforms") or [])
    chosen = list(dict.fromkeys(chosen))  # Drop repeats, keep the order.
    if not chosen:
        raise BuildError("no platforms to build: the manifest declares none and --platforms is empty")
    return chosen


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--platforms", help="comma-separated subset, e.g. linux-x64 (default: all in the manifest)")
    parser.add_argument("--pythons", help="comma-separated Pythons, e.g. 3.11 (default: every one with wheels)")
    parser.add_argument("--out", default=str(REPO_ROOT / "dist"), help="output folder (default: dist/)")
    parser.add_argument("--cache", default=str(REPO_ROOT / "build" / "wheels_cache"),
                        help="wheel download cache (default: build/wheels_cache/)")
    parser.add_argument("--stage", default=str(REPO_ROOT / "build" / "stage"),
                        help="staging folder, wiped each run (default: build/stage/)")
    parser.add_argument("--source", default=str(REPO_ROOT), help="extension source folder (default: repo root)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Build, print what was built, and return the exit code."""
    args = parse_args(argv)
    try:
        zips = build(args)
    except BuildError as ex:
        print("build_extension: ERROR: {}".format(ex), file=sys.stderr)
        return 1
    for path in zips:
        with zipfile.ZipFile(path) as zf:
            manifest = tomllib.loads(zf.read(MANIFEST).decode("utf-8"))
        versions = "Blender {} to {}".format(manifest["blender_version_min"],
                                             "before " + manifest["blender_version_max"]
                                             if "blender_version_max" in manifest else "any later")
        print("built {} ({:.1f} MiB; {})".format(path, path.stat().st_size / 2**20, versions))
    return 0


if __name__ == "__main__":
    sys.exit(main())
