# Stage "evaluate": official metrics of one submission with the dataset's evaluator (nuScenes TrackingEval or
# the fast exact one; the official AV2 evaluation) as a metrics JSON; experiments with evaluator none (nuScenes
# test) have no evaluation.


def _eval_inputs(w):
    exp = experiment(w)
    return {"submission": S.submission_file(config, w.experiment, w.detector, w.run),
            "data": dataset_input(exp["dataset"], exp["split"])}


rule evaluate:
    input: unpack(_eval_inputs)
    output: "reports/metrics/{experiment}/{detector}/{run}.json"
    params:
        data=lambda w: S.dataset_args(config, experiment(w)["dataset"], experiment(w)["split"]),
        evaluator=lambda w: experiment(w)["evaluator"],
        code=code_version("evaluate"),
    threads: lambda w: S.evaluation_threads(config, experiment(w)["dataset"])
    log: "logs/evaluate/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/evaluate/{experiment}/{detector}/{run}.tsv"
    shell:
        "{GRUTRACK} evaluate {params.data} --submission {input.submission} --evaluator {params.evaluator} "
        "--workers {threads} --out {output} > {log} 2>&1 " + ON_FAIL
