# The 39-candidate study of Zheng et al. 2021 Sec. 5.3 (mcbench.analysis.study):
# the pool's scores beside the paper's Table 3, recommendations derived from the data with their
# stability under scene resampling (among all 31 ensembles and among the 12 the paper names; relMSE
# and DSSIM side by side with a combined rule of ours), the paper's findings with verdicts (finding
# (b) per size-2 ensemble and member in pair_members), bootstrap intervals, and
# the study's figures (error and score curves, score against size, speed against score, equal
# time). Ranked over the pool and the noisy input only (RANKED, common.smk).

STUDY_DIR = f"{RESULTS}/tables/study"
STUDY_FIGURES_DIR = f"{RESULTS}/figures/study"


rule study_tables:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        # summary.md ends with the run's provenance block (provenance.smk)
        manifest=rules.provenance_manifest.output.json,
    output:
        paper=report(
            f"{STUDY_DIR}/paper_table3.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "beside the paper's Table 3"},
        ),
        paper_csv=f"{STUDY_DIR}/paper_table3.csv",
        recommendations=report(
            f"{STUDY_DIR}/recommendations.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "recommendations"},
        ),
        recommendations_csv=f"{STUDY_DIR}/recommendations.csv",
        recommendations_metrics=report(
            f"{STUDY_DIR}/recommendations_metrics.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "recommendations by relMSE and DSSIM together"},
        ),
        recommendations_metrics_csv=f"{STUDY_DIR}/recommendations_metrics.csv",
        findings=report(
            f"{STUDY_DIR}/findings.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "the paper's findings"},
        ),
        findings_csv=f"{STUDY_DIR}/findings.csv",
        pair_members=report(
            f"{STUDY_DIR}/pair_members.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "finding (b): size-2 ensembles against each member"},
        ),
        pair_members_csv=f"{STUDY_DIR}/pair_members.csv",
        reference_noise=report(
            f"{STUDY_DIR}/reference_noise.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "raw against reference-noise-corrected relMSE"},
        ),
        reference_noise_csv=f"{STUDY_DIR}/reference_noise.csv",
        summary=report(
            f"{STUDY_DIR}/summary.md",
            caption="../report/study.rst",
            category="Study",
            subcategory="Tables",
            labels={"table": "summary"},
        ),
        scores_ci=expand(f"{STUDY_DIR}/scores_ci_{{metric}}.csv", metric=METRIC_NAMES),
    params:
        metrics=METRIC_NAMES,
        labels=LABELS,
        entries=[NOISY] + RANKED,
        n_resamples=config["study"]["bootstrap"],
        seed=config["study"]["seed"],
    threads: 1
    resources:
        **job_resources("study_tables"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/study_tables.log",
    script:
        "../scripts/study.py"


rule study_figures:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
        recommendations=rules.study_tables.output.recommendations_csv,
        scores_ci=f"{STUDY_DIR}/scores_ci_{{metric}}.csv",
        renders=expand(rules.render_noisy.output[0], scene=SCENES, spp=SPPS),
    output:
        **{
            key: report(
                f"{STUDY_FIGURES_DIR}/{key}_{{metric}}.png",
                caption="../report/study_figures.rst",
                category="Study",
                subcategory="Figures",
                labels={"metric": "{metric}", "figure": key.replace("_", " ")},
            )
            for key in STUDY_FIGURE_KEYS
        },
    params:
        entries=[NOISY] + RANKED,
        labels=LABELS,
        inputs={name: list(spec.inputs) for name, spec in METHODS.items()},
    threads: 1
    resources:
        **job_resources("study_figures"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/study_figures_{{metric}}.log",
    script:
        "../scripts/study.py"
