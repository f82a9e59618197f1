"""User settings -> core build options and render keywords, validated once.

The panel's PropertyGroup and the command line expose the same names as
:class:`Settings`, so both go through :func:`make_config` and fail with the
same messages. This module imports neither bpy nor core: it is plain data,
testable anywhere, and cheap enough to run when the add-on is enabled.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from .errors import PreviewError

MODES = ("auto", "ao", "shadow", "ao+shadow")
BUILDERS = ("binned", "exact", "median")  # core.build.options.BUILDERS (a test keeps them equal)
OUTPUT_FORMATS = {"PNG": ".png", "OPEN_EXR": ".exr"}
MAX_SAMPLES = 65536
MAX_DEPTH = 60  # core.build.options.DEPTH_LIMIT
MAX_LEAF_SIZE = 1 << 20  # core.build.options' bound
MAX_MEMORY_LIMIT_MB = 1 << 30  # 1 PiB, beyond any machine's memory; the panel's fields stop at these too


class SettingsError(PreviewError, ValueError):
    """A setting is out of range; the message names it and the allowed values, `setting` its name
    (None for a rule on several)."""

    def __init__(self, message: str, setting: str | None = None):
        super().__init__(message)
        self.setting = setting


@dataclass(frozen=True)
class Settings:
    """Every user-facing render setting with its default (0 means "automatic" where noted).

    mode: "ao", "shadow", "ao+shadow" or "auto": ao+shadow when a scene light emits, else ao, decided
        each frame (docs/choices.md#automatic-mode-ao-and-shadows-where-a-light-emits).
    samples: samples per pixel (AO directions / light samples).
    ao_distance: AO ray length in scene units; also how far occluders darken.
    resolution_percentage: percent of the scene's base render resolution (resolution_x/y; the
        scene's own percentage is not applied), so a preview can be much smaller than the final
        render without touching the scene.
    builder, leaf_size, bins: core.BuildOptions fields (defaults equal core's; a test checks).
    max_depth: kd-tree depth limit; 0 = core's automatic 1.2 log2(N) + 2.
    threads: worker threads for build and trace; 0 = every core Numba sees.
    error_target: stop sampling a pixel once its standard error is below this; 0 = off.
    denoise: filter the finished image with core's edge-avoiding à-trous denoiser (core/render/denoise.py),
        which fades out as pixels converge; off by default so the image stays the raw estimate
        (README: "Denoising").
    output_format: "PNG" or "OPEN_EXR" for animation frames.
    seed: sampler seed, so two runs of a frame give the same image.
    memory_limit_mb: refuse a frame whose estimated peak memory (triangles, kd-tree, pixel
        buffers; see memory_limit.py) is above this many MiB, before allocating it; 0 = no limit.
    lazy: build the kd-tree on demand (seed 003): only the parts rays reach; the same image. The
        scene then goes into one flat tree (core.SceneBuilder layout "flat"), since a two-level
        scene's mesh trees are built eagerly. Pays when most of the scene is hidden.
    rebuild_all: build every kd-tree and trace every frame anew, as a fresh process would (turns off
        tree, pixel and image reuse and the layout's memory of earlier frames' motion; for comparisons and
        benchmarks).
    """

    mode: str = "auto"
    samples: int = 16
    ao_distance: float = 1.0
    resolution_percentage: int = 50
    builder: str = "binned"
    leaf_size: int = 2
    max_depth: int = 0
    bins: int = 32
    threads: int = 0
    error_target: float = 0.0
    denoise: bool = False
    output_format: str = "PNG"
    seed: int = 0
    memory_limit_mb: int = 0
    rebuild_all: bool = False
    lazy: bool = False


DEFAULTS = Settings()
AUTOMATIC = "auto"  # report_settings' word for a setting the add-on decides
AUTOMATIC_WHEN = {"mode": "auto", "max_depth": 0, "threads": 0}  # the value that means automatic
OFF_WHEN = {"error_target": 0.0, "memory_limit_mb": 0}  # the value that means off
SETTING_NAMES = tuple(f.name for f in fields(Settings))


@dataclass(frozen=True)
class RenderConfig:
    """Validated settings in the shapes core wants.

    build_options: keywords for core.build_kdtree.
    render_options: the fields of a core.RenderOptions but its lights (a dict: config never imports core).
    """

    settings: Settings
    build_options: dict
    render_options: dict

    @property
    def resolution_percentage(self) -> int:
        return self.settings.resolution_percentage

    @property
    def denoise(self) -> bool:
        """Whether to read the image as PreviewRender.image(denoise=True)."""
        return self.settings.denoise

    @property
    def memory_limit(self) -> int | None:
        """The memory limit in bytes, None for no limit."""
        return self.settings.memory_limit_mb * (1 << 20) or None

    @property
    def file_extension(self) -> str:
        return OUTPUT_FORMATS[self.settings.output_format]

    def as_dict(self) -> dict:
        """The user settings as set (0 for automatic), for the image key."""
        return asdict(self.settings)

    def report_settings(self) -> dict:
        """The user settings for report.json, in one convention: a setting left to the add-on is
        "auto" (mode, max_depth, threads), one turned off is null (error_target, memory_limit_mb); what
        "auto" chose is recorded beside it (the run's threads, each frame's mode and tree depth)."""
        values = asdict(self.settings)
        for name, value in values.items():
            if name in AUTOMATIC_WHEN and value == AUTOMATIC_WHEN[name]:
                values[name] = AUTOMATIC
            elif name in OFF_WHEN and value == OFF_WHEN[name]:
                values[name] = None
        return values


def make_config(source) -> RenderConfig:
    """Validate the settings read from `source` (any object with Settings' attribute names,
    e.g. the scene's KDPreviewSettings or parsed command-line arguments) and map them.

    Raises SettingsError naming the first bad setting.
    """
    values = {name: read_setting(source, name) for name in SETTING_NAMES}
    settings = Settings(**values)
    _validate(settings)
    return RenderConfig(settings, _build_options(settings), _render_options(settings))


class _StoredItem(int):
    """An enum setting's stored number that names none of its items: Blender reads such a setting as ''
    (a file from another version, or a script's item assignment), so the message names the number."""

    def __repr__(self) -> str:
        return f"stored item number {int(self)}, which names none of them"


def read_setting(source, name: str):
    """`source`'s value of setting `name` (the default where it has none); an enum property that reads ''
    gives its stored number (_StoredItem) when `source` keeps one (a property group's `get`), so a copy
    of the settings (the command line's, a farm's) still names it."""
    value = getattr(source, name, getattr(DEFAULTS, name))
    if value == "" and callable(getattr(source, "get", None)):
        stored = source.get(name)
        if isinstance(stored, int) and not isinstance(stored, bool):
            return _StoredItem(stored)
    return value


def _build_options(s: Settings) -> dict:
    return {
        "builder": s.builder,
        "leaf_size": int(s.leaf_size),
        "bins": int(s.bins),
        "max_depth": int(s.max_depth) or None,
        "threads": int(s.threads) or None,
        "lazy": bool(s.lazy),
    }


def _render_options(s: Settings) -> dict:
    return {
        "mode": s.mode,
        "samples": int(s.samples),
        "ao_distance": float(s.ao_distance),
        "error_target": float(s.error_target) or None,
        "threads": int(s.threads) or None,
        "seed": int(s.seed),
    }


def _validate(s: Settings) -> None:
    _choice("mode", s.mode, MODES)
    _choice("builder", s.builder, BUILDERS)
    _choice("output_format", s.output_format, tuple(OUTPUT_FORMATS))
    _integer("samples", s.samples, 1, MAX_SAMPLES)
    _integer("resolution_percentage", s.resolution_percentage, 1, 100)
    _integer("leaf_size", s.leaf_size, 1, MAX_LEAF_SIZE)
    _integer("max_depth", s.max_depth, 0, MAX_DEPTH, "0 = automatic")
    _integer("bins", s.bins, 2, 4096)
    _integer("threads", s.threads, 0, 1024, "0 = all cores")
    _integer("seed", s.seed, 0, 2**31 - 1)
    _integer("memory_limit_mb", s.memory_limit_mb, 0, MAX_MEMORY_LIMIT_MB, "0 = no limit")
    _number("ao_distance", s.ao_distance, positive=True)
    _number("error_target", s.error_target, positive=False, note="0 = off")
    for name in ("rebuild_all", "lazy", "denoise"):
        if not isinstance(getattr(s, name), bool):
            raise SettingsError(f"{name} must be True or False; got {getattr(s, name)!r}", name)


def _choice(name, value, choices) -> None:
    if value not in choices:
        raise SettingsError(f"{name} must be one of {', '.join(choices)}; got {value!r}", name)


def _integer(name, value, low, high, note="") -> None:
    suffix = f" ({note})" if note else ""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise SettingsError(f"{name} must be an integer from {low} to {high}{suffix}; got {value!r}", name)


def _number(name, value, *, positive, note="") -> None:
    ok = not isinstance(value, bool) and isinstance(value, (int, float)) and value == value
    ok = ok and value != float("inf") and (value > 0 if positive else value >= 0)
    if not ok:
        bound = "greater than 0" if positive else "0 or more"
        suffix = f" ({note})" if note else ""
        raise SettingsError(f"{name} must be a finite number {bound}{suffix}; got {value!r}", name)


def frame_size(resolution_x: int, resolution_y: int, percentage: int) -> tuple[int, int]:
    """Preview size in pixels: the scene's resolution scaled as Blender scales it (floor).

    Raises SettingsError when either side comes out below one pixel.
    """
    width = int(resolution_x) * int(percentage) // 100
    height = int(resolution_y) * int(percentage) // 100
    if width < 1 or height < 1:
        raise SettingsError(
            f"the preview would be {width}x{height} pixels: render resolution "
            f"{resolution_x}x{resolution_y} at {percentage}% is too small"
        )
    return width, height
