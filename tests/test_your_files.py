"""Your files are safe with polyjax: the cache deletes only its own entries, nothing is loaded from a folder others
may write, generated code holds user strings only as literals, every output is written whole or not at all and
checked before any work, paths inside input files stay inside their folder, and the page server answers only the
loopback names (docs/robustness.md, "Your files"). One test per item, named after it."""

import ast
import http.client
import importlib.util
import json
import os
import pickle
import socket
import stat
import threading
import warnings

import jax
import numpy as np
import png
import pytest

import polyjax as pj
from polyjax.cli import main

JAX_ENTRY = f"jit_fit-{'ab' * 32}-cache"


def _tree(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ---------------------------------------------------------------- item 1: the cache deletes only its own files
def _users_folder(folder):
    """A folder of the user's own files (three 2 KB .tex files and a note in a subfolder)."""
    (folder / "sub").mkdir(parents=True)
    for i in range(3):
        (folder / f"chapter{i}.tex").write_bytes(b"%" * 2048)
    (folder / "sub" / "notes.md").write_text("mine")
    return _tree(folder)


def test_cache_trim_keeps_foreign_files(tmp_path, capsys, monkeypatch):
    """The issue's reproduction: a run that fails on its first argument trims nothing, and a folder polyjax did not
    create is never trimmed or cleared (clear says why)."""
    folder = tmp_path / "thesis"
    before = _users_folder(folder)
    monkeypatch.setenv("POLYJAX_CACHE_MAX_MB", "0.001")
    assert main(["--cache-dir", str(folder), "fit", "--degree", "x"]) == 2
    assert _tree(folder) == before
    assert main(["--cache-dir", str(folder), "cache", "clear"]) == 2
    assert "not a polyjax cache folder" in capsys.readouterr().err
    assert _tree(folder) == before


def test_cache_clear_removes_only_its_own_entries(tmp_path, capsys):
    """In a folder polyjax made (mode 0700, marked), clear removes JAX's and polyjax's entries by their name
    patterns and leaves any other file; info says what clear would remove."""
    folder = pj.internal.make_cache_folder(tmp_path / "cache")
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    (folder / "polyjax-programs").mkdir()
    (folder / JAX_ENTRY).write_bytes(b"x" * 100)
    (folder / "polyjax-programs" / f"fit-{'0' * 32}.bin").write_bytes(b"y" * 100)
    (folder / "report.tex").write_text("mine")
    (folder / "polyjax-programs" / "notes.txt").write_text("mine too")
    assert main(["--cache-dir", str(folder), "cache", "info"]) == 0
    out = capsys.readouterr().out
    assert "would remove 2 file(s)" in out and "2 other file(s): never removed" in out
    assert main(["--cache-dir", str(folder), "cache", "clear"]) == 0
    assert sorted(p.name for p in folder.rglob("*") if p.is_file()) == ["POLYJAX-CACHE", "notes.txt", "report.tex"]


def test_no_trim_after_a_run_that_never_opened_the_cache(tmp_path, monkeypatch):
    folder = pj.internal.make_cache_folder(tmp_path / "cache")
    (folder / JAX_ENTRY).write_bytes(b"x" * 4096)
    monkeypatch.setenv("POLYJAX_CACHE_MAX_MB", "0.001")
    assert main(["--cache-dir", str(folder), "fit", "--degree", "x"]) == 2
    assert (folder / JAX_ENTRY).is_file()


# ---------------------------------------------------------------- item 2: nothing executed that polyjax did not write
class _Planted:
    """Unpickling this creates the file ``path``: proof that a planted pickle ran."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _tiny_program(folder):
    """A compiled program saved in ``folder`` (polyjax's own format) and its input."""
    x = np.arange(3.0)
    compiled = pj.internal.compile_for_saving(lambda a: {"y": a * 2.0, "n": (a.sum(), None)}, (x,), "saved_tiny")
    path = folder / "polyjax-programs" / f"fit-{'1' * 32}.bin"
    assert pj.internal.save_program(path, compiled, {"backend": "test"})
    return path, x


def test_planted_pickle_not_loaded(tmp_path):
    """A pickle planted as a saved program is never unpickled: the file is refused as not a saved program."""
    programs = tmp_path / "polyjax-programs"
    programs.mkdir(mode=0o700)
    ran = tmp_path / "ran"
    planted = programs / f"fit-{'2' * 32}.bin"
    planted.write_bytes(pickle.dumps(_Planted(ran)))
    with pytest.raises(pj.DataFormatError, match="saved program"):
        pj.internal.load_program(planted)
    assert not ran.exists()


@pytest.mark.slow
def test_planted_pickle_not_run_by_polyjax_fit(tmp_path, capsys, monkeypatch):
    """The issue's reproduction: a pickle planted as ``polyjax-programs/<name>.bin`` is not run by the next fit,
    which compiles afresh and gives the same numbers."""
    monkeypatch.delenv("POLYJAX_SAVED_PROGRAMS", raising=False)
    monkeypatch.delenv(pj.DATA_ENV, raising=False)
    args = ["--cache-dir", str(tmp_path / "cache"), "fit", "--degree", "2", "--json"]
    assert main(args) == 0
    first = {k: v for k, v in json.loads(capsys.readouterr().out).items() if k != "seconds"}
    (saved,) = (tmp_path / "cache" / "polyjax-programs").glob("fit-*.bin")
    ran = tmp_path / "ran"
    saved.write_bytes(pickle.dumps(_Planted(ran)))
    assert main(args) == 0
    again = {k: v for k, v in json.loads(capsys.readouterr().out).items() if k != "seconds"}
    assert not ran.exists() and again == first


def test_saved_program_has_no_pickle_and_its_digest_is_checked(tmp_path):
    path, x = _tiny_program(tmp_path)
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700 and stat.S_IMODE(path.stat().st_mode) == 0o600
    data = path.read_bytes()
    magic, header, payload = data.split(b"\n", 2)
    assert magic == b"polyjax-program 1" and json.loads(header)["extra"] == {"backend": "test"}
    compiled, extra = pj.internal.load_program(path)
    out = compiled(x)
    np.testing.assert_array_equal(out["y"], 2.0 * x)
    assert float(out["n"][0]) == 3.0 and out["n"][1] is None and extra == {"backend": "test"}
    path.write_bytes(magic + b"\n" + header + b"\n" + payload[:-1] + bytes([payload[-1] ^ 1]))
    with pytest.raises(pj.DataFormatError, match="SHA-256"):
        pj.internal.load_program(path)


def test_program_in_a_folder_others_may_write_is_not_loaded(tmp_path):
    """A folder writable by others (a shared /tmp, a restored CI cache): warned once, naming the folder and the
    reason; nothing loaded (and nothing written), and JAX's persistent cache is not turned on there."""
    path, _ = _tiny_program(tmp_path)
    os.chmod(path.parent, 0o777)
    with pytest.warns(UserWarning, match=r"polyjax-programs.*writable by group and others"):
        assert pj.internal.load_program(path) is None
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o777)
    with pytest.warns(UserWarning, match=r"shared.*writable by group and others"):
        pj.enable_compilation_cache(shared)
    assert not jax.config.jax_enable_compilation_cache


# ---------------------------------------------------------------- item 3: user strings in generated code
def _model(batch=()):
    """A polynomial model of degree 1 in the Lafortune variables (``k = 2``), built without a fit."""
    b = tuple(batch)
    return pj.PolynomialBRDF(
        coefficients=np.broadcast_to([0.2, 0.1, 0.05], b + (3,)).copy(), degree=np.ones(b, int),
        mean=np.zeros(b + (2,)), rotation=np.broadcast_to(np.eye(2), b + (2, 2)).copy(), centre=np.zeros(b + (2,)),
        halfwidth=np.ones(b + (2,)), l2=np.zeros(b), rank=np.full(b, 3), condition=np.ones(b),
        n_used=np.full(b, 10), status=np.zeros(b, int), variables="lafortune", basis="monomial",
        interactions=False, max_degree=1)


@pytest.fixture(scope="module")
def saved_model(tmp_path_factory):
    """A small model saved under a file name holding a docstring's quotes."""
    return pj.save_model(tmp_path_factory.mktemp('odd"""name') / 'm"""x.npz', _model())


def test_plugin_name_injection_refused(saved_model, tmp_path, capsys):
    out = tmp_path / "plugin.py"
    assert main(["export", str(saved_model), "--to", "mitsuba", "--out", str(out),
                 "--name", 'x"""\nimport os\n"""']) == 2
    assert "--name" in capsys.readouterr().err and not out.exists()
    with pytest.raises(pj.InputError, match="plugin name"):
        pj.export.register_mitsuba_bsdf(None, "a b")
    with pytest.raises(pj.InputError, match="GLSL function name"):
        pj.export.glsl(pj.load_model(saved_model), name="f(){}//")


def test_generated_plugin_holds_paths_only_as_literals(saved_model, tmp_path):
    out = tmp_path / "plugin.py"
    assert main(["export", str(saved_model), "--to", "mitsuba", "--out", str(out), "--name", "mine"]) == 0
    tree = ast.parse(out.read_text())
    assert str(saved_model.parent.name) not in ast.get_docstring(tree)
    constants = {t.targets[0].id: ast.literal_eval(t.value) for t in tree.body if isinstance(t, ast.Assign)}
    assert constants == {"MODEL": os.path.relpath(saved_model.resolve(), tmp_path.resolve()), "INDEX": None,
                         "NAME": "mine"}
    assert all(not line.lstrip().startswith("#") or '"""' not in line for line in out.read_text().splitlines())


def test_generated_plugin_finds_its_model_after_both_move(tmp_path):
    """The plugin names its model relative to its own folder: moved together (here: a folder renamed), the plugin
    still loads it; the model file is read, nothing else."""
    (tmp_path / "a").mkdir()
    model = pj.save_model(tmp_path / "a" / "m.npz", _model())
    out = tmp_path / "a" / "plugin.py"
    assert main(["export", str(model), "--to", "mitsuba", "--out", str(out)]) == 0
    (tmp_path / "a").rename(tmp_path / "b")
    spec = importlib.util.spec_from_file_location("moved_plugin", tmp_path / "b" / "plugin.py")
    plugin = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(plugin)
    assert plugin.MODEL == "m.npz" and plugin.model_path() == str(tmp_path / "b" / "m.npz")
    loaded = pj.load_model(plugin.model_path())
    u = np.array([[0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(np.asarray(loaded(u, u)), np.asarray(_model()(u, u)))


# ---------------------------------------------------------------- item 5: temporary files
def test_tmp_names_unpredictable_and_no_symlink_follow(tmp_path, saved_model):
    """A link planted at the old predictable name is not followed; temporary names differ between writes, sit in
    the target's folder and keep its suffix; a new file gets the user's usual mode."""
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    target = tmp_path / "model.npz"
    os.symlink(victim, tmp_path / f".{target.name}.{os.getpid()}.tmp")
    pj.save_model(target, pj.load_model(saved_model))
    assert victim.read_bytes() == b"keep me" and pj.load_model(target) is not None
    names = []
    for _ in range(2):
        pj.internal.write_atomically(tmp_path / "x.exr", lambda tmp: (names.append(tmp), tmp.write_bytes(b"1")))
    assert names[0] != names[1] and all(n.parent == tmp_path and n.suffix == ".exr" for n in names)
    umask = os.umask(0o022)
    os.umask(umask)
    assert stat.S_IMODE((tmp_path / "x.exr").stat().st_mode) == 0o666 & ~umask


def test_failed_write_leaves_nothing(tmp_path):
    target = tmp_path / "old.bin"
    target.write_bytes(b"old")

    def interrupted(tmp):
        tmp.write_bytes(b"half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        pj.internal.write_atomically(target, interrupted)
    assert _tree(tmp_path) == ["old.bin"] and target.read_bytes() == b"old"
    with pytest.raises(pj.InputError, match="found a folder"):
        pj.internal.write_bytes_atomically(tmp_path, b"x")


# ---------------------------------------------------------------- item 6: outputs checked before any work
def test_output_checked_before_work_export_rgl_to_missing_folder(tmp_path, capsys):
    assert main(["export", "rgl:no-such-file.bsdf", "--to", "merl", "--out", str(tmp_path / "missing" / "x.binary")]
                ) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "does not exist" in err and "no-such-file" not in err


def test_output_checked_before_work_standard_export_out_folder(tmp_path, capsys):
    assert main(["export", "merl-nbrdf:no-such-material", "--to", "gltf", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "found a folder" in err


def test_output_checked_before_work_render_png(tmp_path, capsys):
    (tmp_path / "grid.png").mkdir()
    assert main(["render", "--out", str(tmp_path / "grid.exr"), "--size", "8"]) == 2
    assert "found a folder" in capsys.readouterr().err and not (tmp_path / "grid.exr").exists()


def test_output_checked_before_work_save_model_onto_folder(tmp_path, saved_model):
    (tmp_path / "m.npz").mkdir()
    with pytest.raises(pj.InputError, match="found a folder"):
        pj.save_model(tmp_path / "m.npz", pj.load_model(saved_model))


def test_output_checked_before_work_busy_port(tmp_path, saved_model, capsys):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        out = tmp_path / "page.html"
        assert main(["view", str(saved_model), "--out", str(out), "--serve", "--port",
                     str(busy.getsockname()[1])]) == 2
    assert "--port" in capsys.readouterr().err and not out.exists()


# ---------------------------------------------------------------- item 8: paths inside input files
def _capture_folder(folder, name):
    folder.mkdir()
    (folder / "filenames.txt").write_text(name + "\n")
    (folder / "light_directions.txt").write_text("0 0 1\n")
    (folder / "light_intensities.txt").write_text("1 1 1\n")
    (folder / "normal.txt").write_text("0 0 1\n" * 4)
    with open(folder / "mask.png", "wb") as f:
        png.Writer(2, 2, greyscale=True, bitdepth=8).write(f, [[255, 255], [255, 255]])
    with open(folder.parent / "outside.png", "wb") as f:
        png.Writer(2, 2, greyscale=False, bitdepth=16).write(f, [[1000] * 6, [1000] * 6])


def test_paths_in_inputs_stay_inside(tmp_path):
    _capture_folder(tmp_path / "capture", "../outside.png")
    with pytest.raises(pj.DataFormatError, match=r"filenames.txt.*line 1.*relative path inside"):
        pj.data.load_photometric(tmp_path / "capture")
    shards = tmp_path / "texture"
    shards.mkdir()
    (shards / "manifest.json").write_text(json.dumps({"format": "polyjax-texture-shards-1"}))
    model = _model((2, 1))
    manifest = pj.svbrdf.write_texture_shards(shards, model)
    meta = json.loads(manifest.read_text())
    meta["shards"][0]["files"]["npz"] = str(tmp_path / "elsewhere.npz")
    manifest.write_text(json.dumps(meta))
    with pytest.raises(pj.DataFormatError, match=r"manifest.*relative path inside"):
        pj.svbrdf.read_texture_shards(shards)
    scene = tmp_path / "scene"
    scene.mkdir()
    pj.render.write_exr(tmp_path / "outside.exr", np.zeros((2, 2, 3)))
    (scene / "scene.json").write_text(json.dumps({"images": [{"file": "../outside.exr", "lights": []}],
                                                  "camera": {}, "objects": []}))
    assert main(["fit-images", str(scene / "scene.json")]) == 2


# ---------------------------------------------------------------- item 9: the page server
def test_serve_rejects_foreign_host():
    server = pj.view.open_server(0)
    server.page = b"<html>page</html>"
    threading.Thread(target=server.serve_forever, daemon=True).start()
    port = server.server_port
    try:
        answers = {}
        for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"evil.example:{port}", "127.0.0.1", None):
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
            conn.putrequest("GET", "/", skip_host=True)
            if host is not None:
                conn.putheader("Host", host)
            conn.endheaders()
            reply = conn.getresponse()
            answers[host] = (reply.status, reply.read())
            conn.close()
    finally:
        server.shutdown()
        server.server_close()
    assert answers[f"127.0.0.1:{port}"] == answers[f"localhost:{port}"] == (200, b"<html>page</html>")
    assert all(answers[h][0] == 403 and b"page</html>" not in answers[h][1]
               for h in (f"evil.example:{port}", "127.0.0.1", None))


def test_untrusted_warning_is_given_once(tmp_path):
    path, _ = _tiny_program(tmp_path)
    os.chmod(path, 0o666)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        for _ in range(3):
            assert pj.internal.load_program(path) is None
    assert len([w for w in seen if "writable by" in str(w.message)]) == 1
