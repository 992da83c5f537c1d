# Stage "evaluate": official metrics of one submission with the dataset's evaluator (nuScenes: the fast exact
# evaluator, or nuscenes-devkit TrackingEval; AV2: the official evaluation) as a metrics JSON; experiments with
# evaluator none (nuScenes test) have no evaluation. An experiment's cross_check run is also scored by both
# nuScenes evaluators (rule cross_check) and its report states whether they agree.


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


def _cross_check_scenes(w):
    n = experiment(w)["cross_check"]["scenes"]
    return f"--scenes {n}" if n else ""


rule cross_check:
    """nuscenes-devkit TrackingEval and the fast evaluator on one run (on `scenes` evenly spaced scenes of the
    split): every entry of the metrics summary compared; fails when they differ by more than 1e-9."""
    input: unpack(_eval_inputs)
    output: "reports/metrics/{experiment}/{detector}/{run}.crosscheck.json"
    params:
        data=lambda w: S.dataset_args(config, experiment(w)["dataset"], experiment(w)["split"]),
        scenes=_cross_check_scenes,
        code=code_version("evaluate"),
    log: "logs/evaluate/{experiment}/{detector}/{run}.crosscheck.log"
    benchmark: "logs/benchmarks/evaluate/{experiment}/{detector}/{run}.crosscheck.tsv"
    shell:
        "{GRUTRACK} cross-check {params.data} --submission {input.submission} {params.scenes} --out {output} "
        "> {log} 2>&1 " + ON_FAIL
