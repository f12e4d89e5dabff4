"""Sun positions (pvlib's NREL SPA) as lights, scene files' [sun] and [[sensors]], sensor grids, and the
sun-hours command end to end."""

import csv
import sys

import numpy as np
import pytest
from PIL import Image

import shadowcl as sc
from conftest import SCENES
from shadowcl.cli import main
from shadowcl.sensors import grid_on_faces, scene_sensors

pd = pytest.importorskip("pandas")
pytest.importorskip("pvlib")
from shadowcl.sun import light_directions, sun_angles, sun_positions, sun_times  # noqa: E402


def test_spa_matches_the_published_example():
    """The worked example of the NREL SPA report (Reda & Andreas 2004, NREL/TP-560-34302, table A5.1),
    which pvlib's own tests use (pvlib/tests/test_solarposition.py, ``expected_solpos``): Golden,
    Colorado, 2003-10-17 12:30:30 local time (UTC-7), 1830.14 m: topocentric elevation 39.872046,
    azimuth 194.340241 degrees. Tolerance 1e-3 degrees: pvlib's default delta T for 2003 differs from
    the report's 67 s by a few seconds, i.e. ~1e-4 degrees of sun."""
    times = pd.DatetimeIndex(["2003-10-17 12:30:30"], tz="Etc/GMT+7")
    position = sun_positions(39.742476, -105.1786, times, altitude=1830.14)
    assert position["elevation"].iloc[0] == pytest.approx(39.872046, abs=1e-3)
    assert position["azimuth"].iloc[0] == pytest.approx(194.340241, abs=1e-3)


def test_noon_sun_is_south_in_the_north_and_north_in_the_south():
    """Scene axes: up +y, north -z (east +x). Near the June solstice noon at 45 N the sun is due south at
    90 - 45 + 23.44 = 68.4 degrees; at 45 S due north at 21.6 degrees."""
    times = pd.DatetimeIndex(["2026-06-21 12:00"], tz="UTC")
    for latitude, elevation, travels_z in ((45.0, 68.4, -1), (-45.0, 21.6, +1)):
        [light] = sc.sun_lights(latitude, 0.0, times)
        e, _ = sun_angles(latitude, 0.0, times)
        assert e[0] == pytest.approx(elevation, abs=0.2)       # noon is ~2 min off 12:00 UTC at lon 0
        d = light.direction
        assert d[1] == pytest.approx(-np.sin(np.radians(e[0])), abs=1e-9)
        assert np.sign(d[2]) == travels_z and abs(d[0]) < 0.02


def test_axes_are_settable():
    """A sun due east at elevation 0 travels west; with up = +z and north = +y, west is -x."""
    d = light_directions([0.0], [90.0], up=(0, 0, 1), north=(0, 1, 0))
    np.testing.assert_allclose(d, [[-1.0, 0.0, 0.0]], atol=1e-12)
    d = light_directions([90.0], [0.0], up=(0, 0, 1), north=(0, 1, 0))
    np.testing.assert_allclose(d, [[0.0, 0.0, -1.0]], atol=1e-12)


def test_only_suns_above_the_horizon():
    times = sun_times("2026-03-20", "2026-03-21", "1h")
    assert len(times) == 24 and str(times.tz) == "UTC"
    suns = sc.sun_lights(0.0, 0.0, times)
    assert 10 <= len(suns) <= 13                     # the equinox on the equator: about 12 hours of day
    assert all(light.direction[1] < 0 for light in suns)
    assert sc.sun_lights(80.0, 0.0, start="2026-12-21", end="2026-12-22") == []    # polar night


def test_a_year_in_a_daylight_saving_timezone():
    """Europe/Paris over 2026: both clock changes crossed, every step one hour of elapsed time (8760),
    and a naive start in the spring gap (02:30 does not exist) taken as the first time after it."""
    times = sun_times("2026-01-01", "2027-01-01", "1h", "Europe/Paris")
    assert len(times) == 8760 and set(np.diff(times.asi8)) == {np.diff(times.asi8)[0]}
    assert str(times.tz) == "Europe/Paris" and times[0].utcoffset() == pd.Timedelta("1h")
    assert sun_times("2026-03-29 02:30", "2026-03-29 05:00", "1h", "Europe/Paris")[0].hour == 3
    assert 4000 < len(sc.sun_lights(48.85, 2.35, start="2026-01-01", end="2027-01-01", timezone="Europe/Paris")) < 4800


@pytest.mark.parametrize("call, error, match", [
    (lambda: sun_times("2026-01-01", "2026-01-02", "1h", "Mars/Base"), ValueError, "timezone"),
    (lambda: sc.sun_lights(91.0, 0.0, start="2026-01-01", end="2026-01-02"), ValueError, "latitude"),
    (lambda: sc.sun_lights(-90.5, 0.0, start="2026-01-01", end="2026-01-02"), ValueError, "latitude"),
    (lambda: sc.sun_lights(10.0, 200.0, start="2026-01-01", end="2026-01-02"), ValueError, "longitude"),
    (lambda: sc.sun_lights(float("nan"), 0.0, start="2026-01-01", end="2026-01-02"), ValueError, "latitude"),
    (lambda: sc.sun_lights("north", 0.0, start="2026-01-01", end="2026-01-02"), TypeError, "latitude"),
    (lambda: sc.sun_lights(10.0, 0.0, start="2026-01-01", end="2026-01-02", step="0h"), ValueError, "step"),
    (lambda: sc.sun_lights(10.0, 0.0, start="2026-01-01", end="2026-01-02", step="-1h"), ValueError, "step"),
    (lambda: sc.sun_lights(10.0, 0.0, start="2026-01-01", end="2026-01-02", step="often"), ValueError, "step"),
    (lambda: sc.sun_lights(10.0, 0.0, start="2026-01-02", end="2026-01-01"), ValueError, "empty"),
    (lambda: sc.sun_lights(10.0, 0.0), ValueError, "times"),
    (lambda: sc.sun_lights(10.0, 0.0, ["2026-01-01"]), TypeError, "times"),
    (lambda: light_directions([10.0], [0.0], up=(0, 1, 0), north=(0, 2, 0)), ValueError, "north"),
])
def test_bad_sun_input(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_grid_on_a_box_top():
    """A 4 x 4 box top at spacing 1: the 5 x 5 lattice points, each once (two triangles share the
    diagonal), lifted onto it and moved 0.01 along its normal; its sides and bottom carry none."""
    box = sc.Scene.load(SCENES / "default.toml").objects[0][1]        # the ground slab, top at y = 0
    small = sc.Mesh(box.vertices * np.float32(4 / 30), box.faces)    # 4 x 4, top at y = 0
    points, normals = grid_on_faces([small], 1.0, 0.01)
    assert len(points) == 25
    np.testing.assert_allclose(np.sort(np.unique(points[:, 0])), [-2, -1, 0, 1, 2], atol=1e-6)
    np.testing.assert_allclose(points[:, 1], 0.01, atol=1e-6)
    np.testing.assert_allclose(normals, np.tile([0, 1, 0], (25, 1)), atol=1e-6)
    with pytest.raises(ValueError, match="spacing"):
        grid_on_faces([small], 0.0)


def test_city_block_scene_has_its_site_and_sensor_grids():
    scene = sc.Scene.load(SCENES / "city_block.toml")
    assert scene.sun["latitude"] == pytest.approx(48.8566) and scene.sun["step"] == "1h"
    assert len(scene.objects) == 37 and [s["name"] for s in scene.sensors] == ["ground", "roofs"]
    grids = scene_sensors(scene)
    assert len(grids[0].points) == 101 * 101            # 200 m at 2 m, both ends included
    assert len(grids[1].points) > 1000 and grids[1].points[:, 1].min() > 1   # on the roofs, none on the ground


def test_a_spacing_too_fine_to_fit_is_refused_before_allocating():
    """1e-5 m over the city block's 200 m ground (a 2e7 x 2e7 lattice, terabytes) is a ValueError naming
    spacing and the count, from the grid itself and through a scene's sensors; a fine grid that fits is kept."""
    scene = sc.Scene.load(SCENES / "city_block.toml")
    with pytest.raises(ValueError, match=r"spacing: 1e-05 puts [0-9.]+e\+14 lattice points"):
        scene_sensors(scene, spacing=1e-5)
    ground = dict(scene.objects)[scene.sensors[0]["objects"][0]]
    with pytest.raises(ValueError, match=r"spacing: 1e-05 puts [0-9.]+e\+14 lattice points"):
        grid_on_faces([ground], 1e-5)
    small = sc.Mesh(ground.vertices * np.float32(0.05), ground.faces)    # 10 m at 5 cm: fits
    assert len(grid_on_faces([small], 5e-2)[0]) == 201 * 201


SENSOR_SCENE = """
[[lights]]
type = "directional"
direction = [0, -1, 0]
[[objects]]
name = "ground"
box = { size = [10, 1, 10], center = true }
[[objects]]
name = "tower"
box = { size = [1, 3, 1] }
"""


@pytest.mark.parametrize("extra, match", [
    ("[sun]\nlatitude = 95.0\nlongitude = 0.0\nstart = '2026-01-01'\nend = '2026-01-02'", "sun.latitude: must be within"),
    ("[sun]\nlatitude = 45.0\nlongitude = 0.0\nstart = 3\nend = '2026-01-02'", "sun.start"),
    ("[sun]\nlatitude = 45.0\nlongitude = 0.0\nend = '2026-01-02'", "sun.start: missing"),
    ("[sun]\nlatitude = 45.0\nlongitude = 0.0\nstart = 2026-01-01\nend = 2026-01-02\nhemisphere = 'N'", "hemisphere"),
    ("[[sensors]]\nobjects = ['roof']\nspacing = 1.0", "sensors\\[0\\].objects: no object named roof"),
    ("[[sensors]]\nobjects = ['tower']\nspacing = 0", "sensors\\[0\\].spacing: must be positive"),
    ("[[sensors]]\nobjects = 'tower'\nspacing = 1", "sensors\\[0\\].objects: expected a non-empty array"),
    ("[[sensors]]\nobjects = ['tower']\nspacing = 1\noffset = -1", "offset: must not be negative"),
])
def test_bad_sun_and_sensor_tables(tmp_path, extra, match):
    path = tmp_path / "bad.toml"
    path.write_text(SENSOR_SCENE + extra)
    with pytest.raises((ValueError, TypeError), match=match):
        sc.Scene.load(path)


def test_sun_hours_command_end_to_end(tmp_path, capsys):
    """A spring day on a tower over a ground slab: the .npy and .csv agree, the hours equal the steps
    minus the sum of sc.shadow_mask over the same suns, and the PNG carries the colour bar."""
    scene_file = tmp_path / "tower.toml"
    scene_file.write_text(SENSOR_SCENE + "[[sensors]]\nname = 'all'\nobjects = ['ground', 'tower']\nspacing = 0.5\n"
                          "[sun]\nlatitude = 40.0\nlongitude = -3.7\nstart = 2026-04-10\nend = 2026-04-11\nstep = '30min'\n")
    out = tmp_path / "out" / "hours.png"
    assert main(["sun-hours", str(scene_file), "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    hours = np.load(out.with_suffix(".npy"))
    with out.with_suffix(".csv").open() as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == len(hours) == 21 * 21 + 9        # ground 10 m at 0.5 m, the tower's 1 m top at 0.5 m
    np.testing.assert_array_equal([float(row["hours"]) for row in rows], hours)
    scene = sc.Scene.load(scene_file)
    [grid] = scene_sensors(scene)
    np.testing.assert_allclose([[float(row[k]) for k in "xyz"] for row in rows], grid.points, rtol=1e-5, atol=1e-5)
    suns = sc.sun_lights(40.0, -3.7, start="2026-04-10", end="2026-04-11", step="30min")
    lit = sum((~sc.shadow_mask(scene, sun, grid.points, grid.normals)).astype(float) for sun in suns)
    np.testing.assert_array_equal(hours, 0.5 * lit)
    # the roof sees every sun, the tower's shadow takes hours from the ground, under its footprint none
    assert hours.max() == 0.5 * len(suns) and hours.min() == 0 and np.any((0 < hours) & (hours < hours.max()))
    image = np.asarray(Image.open(out).convert("RGB"))
    assert image.shape[0] > 300 and image.shape[1] > image.shape[0]    # the map and the colour bar beside it


def test_sun_hours_command_errors(tmp_path, capsys):
    scene_file = tmp_path / "plain.toml"
    scene_file.write_text(SENSOR_SCENE)
    assert main(["sun-hours", str(scene_file), "--out", str(tmp_path / "x.png"), "--lat", "10", "--lon", "0",
                 "--start", "2026-01-01", "--end", "2026-01-02"]) == 2
    assert "no [[sensors]]" in capsys.readouterr().err
    assert main(["sun-hours", str(SCENES / "city_block.toml"), "--step", "0h", "--out", str(tmp_path / "x.png")]) == 2
    assert "step" in capsys.readouterr().err
    scene_file.write_text(SENSOR_SCENE + "[[sensors]]\nobjects = ['ground']\nspacing = 1\n")
    assert main(["sun-hours", str(scene_file), "--out", str(tmp_path / "x.png")]) == 2
    assert "pass --lat, --lon, --start, --end" in capsys.readouterr().err
    site = ["--lat", "10", "--lon", "0", "--start", "2026-01-01", "--end", "2026-01-02", "--out", str(tmp_path / "x.png")]
    assert main(["sun-hours", str(scene_file), *site, "--spacing", "0"]) == 2      # not the scene's spacing
    assert "spacing: must be a positive distance, got 0" in capsys.readouterr().err


@pytest.mark.parametrize("module, extra, options", [
    ("pvlib", "shadowcl[sun]", []), ("dask.distributed", "shadowcl[distributed]", ["--workers", "1"])])
def test_sun_hours_command_names_a_missing_extra(module, extra, options, tmp_path, capsys, monkeypatch):
    """A missing extra: one line naming it, exit 2 (no traceback)."""
    monkeypatch.setitem(sys.modules, module, None)      # import of a None entry raises ImportError
    scene_file = tmp_path / "plain.toml"
    scene_file.write_text(SENSOR_SCENE + "[[sensors]]\nobjects = ['ground']\nspacing = 1\n")
    args = ["sun-hours", str(scene_file), "--lat", "10", "--lon", "0", "--start", "2026-01-01", "--end", "2026-01-02",
            "--out", str(tmp_path / "x.png")]
    assert main(args + options) == 2
    err = capsys.readouterr().err
    assert extra in err and err.count("\n") == 1


def test_heat_map_is_drawn_with_the_scenes_north(tmp_path, monkeypatch):
    """north = +x: the result keeps it and the heat map is drawn with it (not the default -z)."""
    from shadowcl import sunhours

    scene_file = tmp_path / "plain.toml"
    scene_file.write_text(SENSOR_SCENE + "[[sensors]]\nobjects = ['ground']\nspacing = 1\n")
    result = sunhours.sun_hours(sc.Scene.load(scene_file), 10.0, 0.0, "2026-01-01 00:00", "2026-01-01 03:00",
                                north=(1.0, 0.0, 0.0))                  # night: no sun, no shadow work
    assert result.north == (1.0, 0.0, 0.0)
    drawn = {}
    monkeypatch.setattr(sunhours, "heat_map", lambda *args, **kwargs: drawn.update(kwargs))
    sunhours.write(result, tmp_path / "x.png")
    assert drawn["north"] == (1.0, 0.0, 0.0)
