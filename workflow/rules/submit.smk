# Stage "submit": the tracker's output validated against the official format and written to submissions/ with
# a manifest (detections, checkpoint, tracker config hash, package and code version); leaderboard zips for
# experiments with a leaderboard_run (nuScenes test: submissions/nusc_test_<detector>.zip).


def _submit_inputs(w):
    exp, run = experiment(w), run_of(w)
    out = {"tracks": S.tracks_file(config, w.experiment, w.detector, w.run),
           "preset": f"results/{w.experiment}/{w.detector}/{w.run}/tracker.yaml",
           "detections": S.detections_file(config, exp["dataset"], exp["split"], w.detector),
           "data": dataset_input(exp["dataset"], exp["split"])}
    if run["training"]:
        out["checkpoint"] = S.checkpoint_file(run["training"])
    return out


def _provenance_args(w, input):
    args = f"--detections {input.detections} --tracker-config {input.preset} --tracker {run_of(w)['tracker']}"
    return args + (f" --checkpoint {input.checkpoint}" if run_of(w)["training"] else "")


def _leaderboard_experiments():
    return [n for n, e in config["experiments"].items() if e["leaderboard_run"]]


rule submit:
    input: unpack(_submit_inputs)
    output:
        submission="submissions/{experiment}/{detector}/{run}.json",
        manifest="submissions/{experiment}/{detector}/{run}.manifest.json",
    wildcard_constraints:
        experiment=NUSC_EXPERIMENTS,
    params:
        dataroot=lambda w: dataroot(experiment(w)["dataset"]),
        version=lambda w: S.version_for(config, experiment(w)["dataset"], experiment(w)["split"]),
        split=lambda w: experiment(w)["split"],
        provenance=_provenance_args,
        track_code=code_version("track"),
        code=code_version("submit"),
    log: "logs/submit/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/submit/{experiment}/{detector}/{run}.tsv"
    shell:
        "{GRUTRACK} submit --tracks {input.tracks} --dataroot {params.dataroot:q} --version {params.version} "
        "--split {params.split} --out {output.submission} --manifest {output.manifest} {params.provenance} "
        "--code-version {params.track_code} > {log} 2>&1 " + ON_FAIL


rule submit_av2:
    input: unpack(_submit_inputs)
    output:
        submission="submissions/{experiment}/{detector}/{run}.pkl",
        manifest="submissions/{experiment}/{detector}/{run}.manifest.json",
    wildcard_constraints:
        experiment=AV2_EXPERIMENTS,
    params:
        dataroot=lambda w: dataroot(experiment(w)["dataset"]),
        split=lambda w: experiment(w)["split"],
        rate=lambda w: config["datasets"][experiment(w)["dataset"]]["rate_hz"],
        provenance=_provenance_args,
        track_code=code_version("track_av2"),
        code=code_version("submit"),
    log: "logs/submit/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/submit/{experiment}/{detector}/{run}.tsv"
    shell:
        "{GRUTRACK} submit --dataset av2 --tracks {input.tracks} --dataroot {params.dataroot:q} "
        "--split {params.split} --rate {params.rate} --out {output.submission} --manifest {output.manifest} "
        "{params.provenance} --code-version {params.track_code} > {log} 2>&1 " + ON_FAIL


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
