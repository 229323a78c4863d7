"""The method registry (methods/__init__.py): finding method modules, and errors that name the config key."""

import pytest

from methods import UnknownMethodError, available_methods, load_method


def test_registry_finds_methods_and_names_bad_keys():
    assert {"oidn", "jbf", "ensemble"} <= set(available_methods())
    assert load_method("oidn", kind="denoiser").METHOD.kind == "denoiser"
    with pytest.raises(UnknownMethodError, match=r"denoisers\[3\].*'oidm'"):
        load_method("oidm", config_key="denoisers[3]")
    with pytest.raises(UnknownMethodError, match="combiners.*not a combiner"):
        load_method("oidn", kind="combiner", config_key="combiners[0]")
