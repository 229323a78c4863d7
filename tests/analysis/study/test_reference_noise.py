"""mcbench.analysis.study.reference_noise: raw against reference-noise-corrected relMSE."""

from __future__ import annotations


import pytest

from mcbench.analysis import pool
from mcbench.analysis.study.data import study_data
from mcbench.analysis.study.reference_noise import reference_noise_effect
from mcbench.analysis.study.markdown import reference_noise_markdown
from tests.analysis.study.synthetic import ALL, FAST, from_orders


def test_reference_noise_effect_names_the_spp_where_the_ranking_really_moves():
    # raw: the same order everywhere; corrected: #10 and #15 swap at 1024 spp in every scene (the
    # reference noise had hidden #15's lead there) -> a real change at 1024 only
    names = [n for n in ALL if pool.candidate(n).size <= 2]
    head = [n for n in names if not pool.candidate(n).is_base]

    def raw_order(scene, spp):
        return head

    def corrected_order(scene, spp):
        if spp != 1024:
            return head
        swap = {"ens10": "ens15", "ens15": "ens10"}
        return [swap.get(n, n) for n in head]
    raw = study_data(from_orders(raw_order, scenes=list("abcd"), spps=(4, 1024), names=names), "relmse",
                           candidates=names)
    corrected = study_data(from_orders(corrected_order, scenes=list("abcd"), spps=(4, 1024), names=names,
                                              metric="relmse_corrected"), "relmse_corrected", candidates=names)
    table = reference_noise_effect(raw, corrected, resampling=FAST).set_index("spp")
    assert table.loc["4", "agree"] == "yes" and table.loc["4", "kendall_tau"] == pytest.approx(1.0)
    assert table.loc["1024", "agree"] == "no"
    assert set(table.loc["1024", "changed"].split()) == {"ens10", "ens15"}
    gap = head.index("ens15") - head.index("ens10")                      # places between them
    assert table.loc["1024", "max_abs_change"] == pytest.approx(gap)
    assert head.index("ens10") < 3 and table.loc["1024", "top_corrected"].split()[head.index("ens10")] == "ens15"
    text = reference_noise_markdown(table.reset_index())
    assert "really changes scores at spp 1024" in text
    with pytest.raises(Exception, match="different"):
        reference_noise_effect(raw, study_data(from_orders(raw_order, scenes=list("ab"), spps=(4,),
                                                                        names=names), "relmse", candidates=names))
