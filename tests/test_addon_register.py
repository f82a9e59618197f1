"""Registration leaves nothing behind, enabling is light, the panel draws every statistic."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from tests.addon_support import REPO, run_python

import bpy  # noqa: E402

import kd_addon  # noqa: E402
from kd_addon import cli, corelib, live_update, operators, panel, properties  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402

CLASSES = properties.CLASSES + operators.CLASSES + panel.CLASSES


def registered_names():
    return {cls.__name__ for cls in CLASSES if cls.is_registered}


HANDLER_KINDS = ("frame_change_post", "depsgraph_update_post", "undo_post", "redo_post", "save_pre", "load_post")


def our_handlers():
    return [h for kind in HANDLER_KINDS for h in getattr(bpy.app.handlers, kind)
            if getattr(h, "__module__", "").startswith("kd_addon.")]


def test_register_unregister_twice_leaves_nothing():
    scenes.reset()
    for _ in range(2):
        kd_addon.register()
        assert registered_names() == {cls.__name__ for cls in CLASSES}
        assert hasattr(bpy.types.Scene, "kd_preview") and hasattr(bpy.types.WindowManager, "kd_preview_state")
        assert hasattr(bpy.ops.kdpreview, "render") and bpy.ops.kdpreview.render.poll() is not None
        assert len(our_handlers()) == len(HANDLER_KINDS) and cli._handle is not None
        kd_addon.unregister()
        assert registered_names() == set()
        assert not hasattr(bpy.types.Scene, "kd_preview")
        assert not hasattr(bpy.types.WindowManager, "kd_preview_state")
        assert our_handlers() == [] and cli._handle is None
        assert not bpy.app.timers.is_registered(live_update.render_edits)


def test_registering_again_re_registers():
    scenes.reset()
    kd_addon.register()
    try:
        kd_addon.register()  # twice: no Blender ValueError "already registered as a subclass"
        assert registered_names() == {cls.__name__ for cls in CLASSES}
        assert len(our_handlers()) == len(HANDLER_KINDS)
        assert bpy.ops.kdpreview.render.poll() is not None
    finally:
        kd_addon.unregister()
    assert registered_names() == set() and our_handlers() == []


def test_handler_never_stacks():
    live_update.register()
    live_update.register()
    try:
        assert [h.__name__ for h in our_handlers()] == ["kd_preview_frame_change", "kd_preview_scene_edit"]
    finally:
        live_update.unregister()
    assert our_handlers() == []


def test_enabling_does_not_import_numba_or_core():
    """Enabling must be instant: numba, llvmlite and core load on the first render only."""
    code = ("import sys, bpy, kd_addon; kd_addon.register(); "
            "bad = [m for m in ('numba', 'llvmlite', 'core') if m in sys.modules]; "
            "kd_addon.unregister(); print(bad); sys.exit(1 if bad else 0)")
    proc = run_python(code)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_root_package_registers_the_addon(tmp_path):
    """The repo root is the extension package (installed as bl_ext.<repo>.kd_preview): importing it
    as a package registers the add-on, and kd_addon finds core as its sibling, not top-level."""
    (tmp_path / "kd_preview").symlink_to(REPO, target_is_directory=True)
    code = ("import sys, bpy; sys.path.insert(0, {!r}); import kd_preview; "
            "kd_preview.register(); assert hasattr(bpy.types.Scene, 'kd_preview'); kd_preview.unregister(); "
            "assert not hasattr(bpy.types.Scene, 'kd_preview'); "
            "from kd_preview.kd_addon import corelib; "
            "assert corelib.core_module_name() == 'kd_preview.core', corelib.core_module_name(); "
            "assert corelib.extension_package('bl_ext.user_default.kd_preview.kd_addon') == "
            "'bl_ext.user_default.kd_preview'; print('ok')").format(str(tmp_path))
    proc = run_python(code, cwd=tmp_path)
    assert proc.returncode == 0 and "ok" in proc.stdout, proc.stdout + proc.stderr


class RecordingLayout:
    """Stands in for bpy's UILayout (which only exists while Blender draws): records the text."""

    def __init__(self, texts):
        self.texts = texts

    def __getattr__(self, name):
        def call(*args, **kwargs):
            if "text" in kwargs:
                self.texts.append(kwargs["text"])
            return RecordingLayout(self.texts)
        return call

    def __setattr__(self, name, value):
        if name == "texts":
            object.__setattr__(self, name, value)


def draw_texts(panel_cls, context):
    texts = []
    panel_cls.draw(SimpleNamespace(layout=RecordingLayout(texts)), context)
    return texts


def test_panels_draw_settings_status_and_last_run():
    scenes.reset()
    kd_addon.register()
    try:
        context = bpy.context
        state = context.window_manager.kd_preview_state
        assert draw_texts(panel.KDPREVIEW_PT_last_run, context) == ["No run yet"]
        properties.set_last_run(state, {"frame": 1, "width": 64, "height": 32, "triangles": 1234, "objects": 3, "lights": 1,
                            "extract_ms": 1.5, "build_ms": 2.5, "trace_ms": 30.0, "total_ms": 35.0,
                            "rays": 99999, "mrays_per_s": 3.3, "first_run": True, "warnings": ["camera shift"],
                            "tree": {"nodes": 7, "leaves": 4, "empty_leaves": 1, "max_depth": 3,
                                     "sah_cost": 12.5, "references_per_triangle": 1.25}})
        texts = draw_texts(panel.KDPREVIEW_PT_last_run, context)
        for expected in ("1,234", "64 x 32", "2.5 ms", "35.0 ms", "99,999", "3.30 Mrays/s", "7", "12.50", "1.25",
                         "camera shift", "Includes loading kernels"):
            assert expected in texts, expected
        state.running, state.status, state.progress = True, "Compiling kernels (first run)…", 0.0
        assert "Compiling kernels (first run)…" in draw_texts(panel.KDPREVIEW_PT_panel, context)
        for cls in (panel.KDPREVIEW_PT_tree, panel.KDPREVIEW_PT_output):
            draw_texts(cls, context)
        assert json.loads(state.last_run)["triangles"] == 1234
    finally:
        kd_addon.unregister()


def test_a_long_status_is_wrapped_to_the_sidebar_not_cut():
    """Blender's labels do not wrap: the sidebar cut a finished status and would cut an error's
    naming of the object at fault. Lines fit the region's width (40 characters without a region)."""
    scenes.reset()
    kd_addon.register()
    try:
        state = bpy.context.window_manager.kd_preview_state
        state.running = False
        state.status = ("Error: object 'Very Long Object Name.001' has a non-finite vertex coordinate (NaN or "
                        "inf) in triangle 12345: fix the mesh or hide the object from renders")
        narrow = SimpleNamespace(region=SimpleNamespace(width=210), preferences=bpy.context.preferences,
                                 scene=bpy.context.scene, window_manager=bpy.context.window_manager)
        for context, chars in ((bpy.context, 40), (narrow, 210 // 7)):
            lines = draw_texts(panel.KDPREVIEW_PT_panel, context)
            lines = lines[next(i for i, t in enumerate(lines) if t.startswith("Error")):]
            assert len(lines) > 1 and max(map(len, lines)) <= chars and " ".join(lines) == state.status
    finally:
        kd_addon.unregister()


def test_cli_command_registration_round_trip():
    cli.register()
    first = cli._handle
    cli.register()  # re-registering replaces, never duplicates
    assert cli._handle is not None and cli._handle is not first
    cli.unregister()
    cli.unregister()
    assert cli._handle is None
    with pytest.raises(ValueError):
        bpy.utils.unregister_cli_command(first)


def test_the_cache_is_warm_only_once_the_sampling_kernel_is_compiled_for_this_python(tmp_path, monkeypatch):
    """The first run's status says "Loading" only when the longest kernel is cached for this Python:
    the first index file appears seconds into a compile of minutes."""
    import sys

    import core.render.render_kernels

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    folder = corelib.numba_cache_dir() / "core_0123"
    folder.mkdir(parents=True)
    module, function = corelib.WARM_KERNEL.split(".")
    assert module == "render_kernels" and hasattr(core.render.render_kernels, function)
    python = f"py{sys.version_info[0]}{sys.version_info[1]}"
    (folder / f"pools.ensure_refs-12.{python}.nbi").touch()
    (folder / f"{corelib.WARM_KERNEL}-43.py30.nbi").touch()  # another Python's
    assert not corelib.cache_is_warm()
    (folder / f"{corelib.WARM_KERNEL}-43.{python}.nbi").touch()
    assert corelib.cache_is_warm()


def test_numba_cache_folder_follows_the_core_sources(tmp_path):
    """Numba checks a cached kernel against its own file only, so a changed callee in another file
    would leave a stale caller: the cache folder is named by a digest of every core source file."""
    copy = tmp_path / "core"
    for path in (REPO / "core").rglob("*.py"):  # the sources of every subpackage too
        target = copy / path.relative_to(REPO / "core")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(path.read_bytes())
    assert corelib.source_digest(copy) == corelib.source_digest()
    edited = copy / "build" / "split_binned.py"
    edited.write_bytes(edited.read_bytes() + b"\n")
    assert corelib.source_digest(copy) != corelib.source_digest()
    versioned = corelib._versioned(tmp_path / "cache")
    assert versioned.parent == tmp_path / "cache" and versioned.name == f"core-{corelib.source_digest()}"
    assert corelib._versioned(versioned) == versioned  # a child process inheriting the folder keeps it


def test_a_blend_relative_output_folder_sets_without_a_warning():
    """The default output folder is "//kd_preview/"; where Blender knows blend-relative paths (4.5 on)
    setting one must not warn 'does not support blend relative "//" prefix' (as in Blender 5.2)."""
    import warnings

    scenes.reset()
    kd_addon.register()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            bpy.context.scene.kd_preview.output_dir = "//elsewhere/"
        assert bpy.context.scene.kd_preview.output_dir == "//elsewhere/"
        if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties:
            assert [str(w.message) for w in caught] == []
    finally:
        kd_addon.unregister()


def test_a_script_that_exits_registered_is_unregistered_at_exit():
    """The bpy 4.2 module crashed at exit (SIGSEGV, exit code 139) when a script registered the add-on
    and did not unregister it (its teardown fails on classes holding Python functions); the bpy module
    now unregisters it at exit. Run with this test's own Python, so each bpy pass checks its Blender.
    The script's own exit hook, registered first, runs last and sees the add-on unregistered."""
    script = ("import atexit, bpy, kd_addon\n"
              "atexit.register(lambda: print('registered at exit:', hasattr(bpy.types.Scene, 'kd_preview')))\n"
              "kd_addon.register()\n"
              "bpy.context.scene.kd_preview.samples = 2\n")
    done = run_python(script, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "registered at exit: False" in done.stdout
    # Enabled as Blender enables add-ons, Blender's own exit disables it again after our hook: no error
    enabled = run_python("import bpy, addon_utils\naddon_utils.enable('kd_addon', default_set=True)\n", timeout=300)
    assert enabled.returncode == 0 and "Traceback" not in enabled.stderr, enabled.stderr[-2000:]
