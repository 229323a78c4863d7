"""The scene table's reference spp: the reference's own (its header), not the config's."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from mcbench import METRICS_COLUMNS
from mcbench.io.exr import write_layers
from mcbench.pipeline.rankings import write_scene_table

SCENE = "cornell_box"


def _scene_table(tmp_path, header_spp):
    color = np.full((8, 8, 3), 0.5, np.float32)
    metadata = {"scene": SCENE, "resolution": "8x8"}
    if header_spp is not None:
        metadata["spp"] = header_spp
    write_layers(tmp_path / "reference.exr", {"color": color, "variance": np.full_like(color, 1e-8)},
                 metadata=metadata)
    rows = [(SCENE, 64, "noisy", "relmse", 1e-2), (SCENE, 64, "oidn", "relmse", 1e-3)]
    pd.DataFrame(rows, columns=list(METRICS_COLUMNS)).to_csv(tmp_path / "metrics.csv", index=False)
    return write_scene_table(str(tmp_path / "metrics.csv"), {SCENE: str(tmp_path / "reference.exr")},
                             {SCENE: 65536}, str(tmp_path / "scenes.csv"), str(tmp_path / "scenes.md"),
                             noisy_records=[], reference_records=[])


@pytest.mark.parametrize("header_spp, shown", [(524288, 524288), (None, 65536)])
def test_the_scene_table_gives_the_spp_its_reference_records(tmp_path, header_spp, shown):
    """A stored reference of 524288 spp where the config asks 65536 is shown as 524288 (the
    store's spp is not the config's); a header without spp (an imported reference) falls back on
    the plan's. Its floor: Var / (r² + 0.01) = 1e-8 / 0.26."""
    table = _scene_table(tmp_path, header_spp)
    assert int(table.loc[0, "reference_spp"]) == shown
    assert table.loc[0, "reference_relmse"] == pytest.approx(1e-8 / 0.26, rel=1e-6)
    assert int(pd.read_csv(tmp_path / "scenes.csv").loc[0, "reference_spp"]) == shown
