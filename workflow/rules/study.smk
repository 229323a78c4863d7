# The 39-candidate study of Zheng et al. 2021 Sec. 5.3 (mcbench.analysis.study):
# the pool's scores beside the paper's Table 3, recommendations derived from the data with their
# stability under scene resampling (among all 31 ensembles and among the 12 the paper names; relMSE
# and DSSIM side by side with a combined rule of ours), the paper's findings with verdicts (finding
# (b) per size-2 ensemble and member in pair_members), bootstrap intervals, and
# the study's figures (error and score curves, score against size, speed against score, equal
# time). Ranked over the pool and the noisy input only (PLAN.ranking.ranked_entries).


rule study_tables:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        # summary.md ends with the run's provenance block (provenance.smk)
        manifest=rules.provenance_manifest.output.json,
    output:
        paper=report(
            "results/tables/study/paper_table3.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "beside the paper's Table 3"},
        ),
        paper_csv="results/tables/study/paper_table3.csv",
        recommendations=report(
            "results/tables/study/recommendations.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "recommendations"},
        ),
        recommendations_csv="results/tables/study/recommendations.csv",
        recommendations_metrics=report(
            "results/tables/study/recommendations_metrics.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "recommendations by relMSE and DSSIM together"},
        ),
        recommendations_metrics_csv="results/tables/study/recommendations_metrics.csv",
        findings=report(
            "results/tables/study/findings.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "the paper's findings"},
        ),
        findings_csv="results/tables/study/findings.csv",
        pair_members=report(
            "results/tables/study/pair_members.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "finding (b): size-2 ensembles against each member"},
        ),
        pair_members_csv="results/tables/study/pair_members.csv",
        reference_noise=report(
            "results/tables/study/reference_noise.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "raw against reference-noise-corrected relMSE"},
        ),
        reference_noise_csv="results/tables/study/reference_noise.csv",
        summary=report(
            "results/tables/study/summary.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "summary"},
        ),
        scores_ci=expand("results/tables/study/scores_ci_{metric}.csv", metric=list(PLAN.ranking.metrics)),
    params:
        metrics=list(PLAN.ranking.metrics),
        labels=dict(PLAN.ranking.labels),
        entries=PLAN.ranking.ranked_entries,
        n_resamples=config["study"]["bootstrap"],
        seed=config["study"]["seed"],
    threads: 1
    resources:
        **STUDY.resources("study_tables"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/study_tables.log",
    script:
        "../scripts/study_tables.py"


rule study_figures:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
        recommendations=rules.study_tables.output.recommendations_csv,
        scores_ci="results/tables/study/scores_ci_{metric}.csv",
        renders=expand(rules.render_noisy.output[0], scene=PLAN.cases.scenes, spp=PLAN.cases.spps),
    output:
        **{
            key: report(
                f"results/figures/study/{key}_{{metric}}.png",
                caption="../report/study_figures.rst",
                category="Study",
                subcategory="Figures",
                labels={"metric": "{metric}", "figure": key.replace("_", " ")},
            )
            for key in STUDY_FIGURES
        },
    params:
        entries=PLAN.ranking.ranked_entries,
        labels=dict(PLAN.ranking.labels),
        inputs=PLAN.method_inputs,
    threads: 1
    resources:
        **STUDY.resources("study_figures"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/study_figures_{metric}.log",
    script:
        "../scripts/study_figures.py"
