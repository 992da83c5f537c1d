# Stage "evaluate": official metrics of one submission (nuScenes TrackingEval or the AV2 evaluator) as a metrics
# JSON; experiments with evaluator none (nuScenes test) have no evaluation.


def _eval_inputs(w):
    exp = experiment(w)
    return {"submission": S.submission_file(config, w.experiment, w.detector, w.run),
            "data": dataset_input(exp["dataset"], exp["split"])}


rule evaluate:
    input: unpack(_eval_inputs)
    output: "reports/metrics/{experiment}/{detector}/{run}.json"
    wildcard_constraints:
        experiment=NUSC_EXPERIMENTS,
    params:
        dataroot=lambda w: dataroot(experiment(w)["dataset"]),
        version=lambda w: S.version_for(config, experiment(w)["dataset"], experiment(w)["split"]),
        split=lambda w: experiment(w)["split"],
        evaluator=lambda w: experiment(w)["evaluator"],
        code=code_version("evaluate"),
    log: "logs/evaluate/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/evaluate/{experiment}/{detector}/{run}.tsv"
    shell:
        "{GRUTRACK} evaluate --dataroot {params.dataroot:q} --version {params.version} --split {params.split} "
        "--submission {input.submission} --evaluator {params.evaluator} --out {output} > {log} 2>&1 " + ON_FAIL


rule evaluate_av2:
    input: unpack(_eval_inputs)
    output: "reports/metrics/{experiment}/{detector}/{run}.json"
    wildcard_constraints:
        experiment=AV2_EXPERIMENTS,
    params:
        dataroot=lambda w: dataroot(experiment(w)["dataset"]),
        split=lambda w: experiment(w)["split"],
        rate=lambda w: config["datasets"][experiment(w)["dataset"]]["rate_hz"],
        code=code_version("evaluate_av2"),
    threads: 2
    log: "logs/evaluate/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/evaluate/{experiment}/{detector}/{run}.tsv"
    shell:
        "{GRUTRACK} evaluate --dataset av2 --dataroot {params.dataroot:q} --split {params.split} "
        "--rate {params.rate} --workers {threads} --submission {input.submission} --out {output} > {log} 2>&1 "
        + ON_FAIL
