"""The suite's own guards: a missing ../shared/models fails the tests that need it, never skips them."""

import pytest

import conftest


@pytest.mark.parametrize("make", [lambda tmp: tmp / "missing", lambda tmp: tmp])   # absent, then empty
def test_missing_models_fail_not_skip(tmp_path, monkeypatch, make):
    monkeypatch.setattr(conftest, "MODELS", make(tmp_path))
    with pytest.raises(pytest.fail.Exception, match="real meshes not found"):
        conftest.require_models()


def test_models_found():
    assert (conftest.require_models() / "stanford-bunny.obj").is_file()
