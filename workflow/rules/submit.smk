# Stage "submit": the tracker's output validated against the dataset's official format and written to
# submissions/ (the dataset's submission file type), its manifest (detections, checkpoint, tracker config hash,
# package and code version) beside it; leaderboard zips for experiments with a leaderboard_run (nuScenes test:
# submissions/nusc_test_<detector>.zip).


def _submit_inputs(w):
    exp, run = experiment(w), run_of(w)
    out = {"tracks": S.tracks_file(config, w.experiment, w.detector, w.run),
           "preset": f"results/{w.experiment}/{w.detector}/{w.run}/tracker.yaml",
           "detections": S.detections_file(config, exp["dataset"], exp["split"], w.detector),
           "data": dataset_input(exp["dataset"], exp["split"])}
    if run["training"]:
        out["checkpoint"] = S.checkpoint_file(config, run["training"])
    return out


def _provenance_args(w, input):
    args = f"--detections {input.detections} --tracker-config {input.preset} --tracker {run_of(w)['tracker']}"
    return args + (f" --checkpoint {input.checkpoint}" if run_of(w)["training"] else "")


def _leaderboard_experiments():
    return [n for n, e in config["experiments"].items() if e["leaderboard_run"]]


rule submit:
    input:
        tracks=lambda w: S.tracks_file(config, w.experiment, w.detector, w.run),
        data=lambda w: dataset_input(experiment(w)["dataset"], experiment(w)["split"]),
    output: "submissions/{experiment}/{detector}/{run}.{ext}"
    wildcard_constraints:
        ext="json|pkl",
    params:
        data=lambda w: S.dataset_args(config, experiment(w)["dataset"], experiment(w)["split"]),
        code=code_version("submit"),
    log: "logs/submit/{experiment}/{detector}/{run}.{ext}.log"
    benchmark: "logs/benchmarks/submit/{experiment}/{detector}/{run}.{ext}.tsv"
    shell:
        "{GRUTRACK} submit {params.data} --tracks {input.tracks} --out {output} --manifest none > {log} 2>&1 "
        + ON_FAIL


rule manifest:
    input:
        unpack(_submit_inputs),
        submission=lambda w: S.submission_file(config, w.experiment, w.detector, w.run),
    output: "submissions/{experiment}/{detector}/{run}.manifest.json"
    params:
        data=lambda w: S.dataset_args(config, experiment(w)["dataset"], experiment(w)["split"]),
        provenance=_provenance_args,
        track_code=code_version("track"),
        code=code_version("submit"),
    log: "logs/submit/{experiment}/{detector}/{run}.manifest.log"
    benchmark: "logs/benchmarks/submit/{experiment}/{detector}/{run}.manifest.tsv"
    shell:
        "{GRUTRACK} manifest {params.data} --submission {input.submission} --out {output} {params.provenance} "
        "--code-version {params.track_code} > {log} 2>&1 " + ON_FAIL


rule leaderboard_zip:
    input:
        submission=lambda w: S.submission_file(config, w.experiment, w.detector, experiment(w)["leaderboard_run"]),
        data=lambda w: dataset_input(experiment(w)["dataset"], experiment(w)["split"]),
    output: "submissions/{experiment}_{detector}.zip"
    wildcard_constraints:
        experiment=_alternation(_leaderboard_experiments()),
    params:
        dataroot=lambda w: dataroot(experiment(w)["dataset"]),
        version=lambda w: S.version_for(config, experiment(w)["dataset"], experiment(w)["split"]),
        split=lambda w: experiment(w)["split"],
        code=code_version("submit"),
    log: "logs/submit/{experiment}_{detector}.zip.log"
    benchmark: "logs/benchmarks/submit/{experiment}_{detector}.zip.tsv"
    shell:
        "{GRUTRACK} leaderboard-zip --submission {input.submission} --dataroot {params.dataroot:q} "
        "--version {params.version} --split {params.split} --out {output} > {log} 2>&1 " + ON_FAIL
