"""The shadowcl command end to end."""

import numpy as np
from PIL import Image

from shadowcl.cli import main

from conftest import PROJECT


def test_render_default_scene_writes_a_png_with_light_and_shadow(tmp_path, capsys):
    out = tmp_path / "demo.png"
    assert main(["render", "--out", str(out), "--size", "160x90"]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out.resolve()}" in printed
    for stage in ("raster", "receivers", "prepare", "classify", "shading"):
        assert f"{stage} " in printed
    image = np.asarray(Image.open(out))
    assert image.shape == (90, 160, 3)
    # The ground (grey) appears both lit and in shadow: bright and dark grey pixels.
    grey = (np.ptp(image.astype(int), axis=2) < 12)
    brightness = image.mean(axis=2)
    assert np.count_nonzero(grey & (brightness > 150)) > 100
    assert np.count_nonzero(grey & (brightness < 110)) > 100


def test_devices_and_methods_are_listed(capsys):
    assert main(["devices"]) == 0
    assert "0:0" in capsys.readouterr().out
    assert main(["methods"]) == 0
    listing = capsys.readouterr().out
    assert "exact" in listing and "resolution" in listing


def test_errors_are_one_line_with_exit_code_2(tmp_path, capsys):
    assert main(["render", str(tmp_path / "missing.toml")]) == 2
    assert "missing.toml" in capsys.readouterr().err
    assert main(["render", "--method", "nope", "--size", "8x8", "--out", str(tmp_path / "x.png")]) == 2
    assert "method: unknown method 'nope'" in capsys.readouterr().err


def test_bad_size_is_a_usage_error(capsys):
    import pytest

    with pytest.raises(SystemExit) as exit_info:
        main(["render", "--size", "wide"])
    assert exit_info.value.code == 2
    assert "--size: expected WIDTHxHEIGHT" in capsys.readouterr().err


def test_output_and_parameter_errors_are_one_line_before_rendering(tmp_path, capsys):
    """--out under a file, with no image suffix, or a float where an integer parameter goes: one line on
    stderr, exit code 2, nothing rendered (these checks come before any OpenCL work)."""
    (tmp_path / "afile").write_text("")
    cases = [
        (["--out", str(tmp_path / "afile" / "x.png")], "--out: cannot make the folder"),
        (["--out", str(tmp_path / "x.foo")], "--out: '.foo' is not an image format"),
        (["--out", str(tmp_path)], "--out: 'no suffix' is not an image format"),
        (["--method", "voxel", "--param", "connectivity=26.0", "--out", str(tmp_path / "v.png"),
          str(PROJECT / "scenes" / "subdivision" / "cube.toml")], "connectivity: expected one of 6, 18, 26, got 26.0"),
        (["--size", "20000x10"], "width: must be between 1 and 16384, got 20000"),
        ([str(tmp_path / "none.toml")], "none.toml: no such scene file"),
        (["--device", "no such device", "--out", str(tmp_path / "d.png")], "no OpenCL device matches"),
    ]
    for args, message in cases:
        assert main(["render", "--size", "8x8", *args]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("shadowcl: error: ") and message in err, err
    assert not list(tmp_path.glob("*.png"))


def test_usage_errors_are_one_line(capsys):
    import pytest

    with pytest.raises(SystemExit) as exit_info:
        main(["render", "--param", "x"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--param: expected NAME=VALUE" in err


def test_default_output_name_stays_in_the_current_folder(tmp_path, monkeypatch, capsys):
    work = tmp_path / "work"
    work.mkdir()
    scene = tmp_path / "s.toml"
    scene.write_text('name = "../../escape"\n[[lights]]\ntype = "point"\nposition = [0, 5, 0]\n'
                     '[[objects]]\nbox = {}\n')
    monkeypatch.chdir(work)
    assert main(["render", str(scene), "--size", "8x8"]) == 0
    assert [path.name for path in work.iterdir()] == ["shadowcl-____escape-exact.png"]
    assert not list(tmp_path.glob("*.png"))
