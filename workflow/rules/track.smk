# Stage "track": one job per (experiment, detector, run). The tracker preset is the shipped one with the
# workflow's overrides, resolved and validated into results/<experiment>/<detector>/<run>/tracker.yaml.


def _track_inputs(w):
    exp, run = experiment(w), run_of(w)
    out = {"data": dataset_input(exp["dataset"], exp["split"]),
           "detections": S.detections_file(config, exp["dataset"], exp["split"], w.detector)}
    if run["training"]:
        out["checkpoint"] = S.checkpoint_file(run["training"])
    return out


def _track_params(w):
    """Everything the tracking job reads from the config, as one value (Snakemake re-runs when it changes)."""
    exp, run = experiment(w), run_of(w)
    ds = config["datasets"][exp["dataset"]]
    data = {"dataroot": ds["dataroot"], "version": S.version_for(config, exp["dataset"], exp["split"]),
            "rate_hz": ds.get("rate_hz")}
    return jq({"data": data, "split": exp["split"], "detector": w.detector,
               "run": run, "preset": config["tracker_presets"][run["preset"]],
               "device": config["tracking"]["device"]})


def _checkpoint_arg(w, input):
    return f"--checkpoint {input.checkpoint}" if run_of(w)["training"] else ""


rule track:
    input: unpack(_track_inputs)
    output:
        tracks="results/{experiment}/{detector}/{run}/tracks.json",
        preset="results/{experiment}/{detector}/{run}/tracker.yaml",
    wildcard_constraints:
        experiment=NUSC_EXPERIMENTS,
    params:
        config=_track_params,
        base=lambda w: config["tracker_presets"][run_of(w)["preset"]]["base"],
        overrides=lambda w: jq(config["tracker_presets"][run_of(w)["preset"]]["overrides"]),
        tracker=lambda w: run_of(w)["tracker"],
        dataroot=lambda w: dataroot(experiment(w)["dataset"]),
        version=lambda w: S.version_for(config, experiment(w)["dataset"], experiment(w)["split"]),
        split=lambda w: experiment(w)["split"],
        checkpoint=_checkpoint_arg,
        device=config["tracking"]["device"],
        code=code_version("track"),
    log: "logs/track/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/track/{experiment}/{detector}/{run}.tsv"
    shell:
        "( {GRUTRACK} resolve-config tracker --base {params.base} --overrides {params.overrides:q} "
        "--out {output.preset} && "
        "{GRUTRACK} track --dataroot {params.dataroot:q} --version {params.version} --split {params.split} "
        "--detections {input.detections} --tracker {params.tracker} --config {output.preset} "
        "{params.checkpoint} --device {params.device} --out {output.tracks} --no-progress ) > {log} 2>&1 "
        + ON_FAIL


rule track_av2:
    input: unpack(_track_inputs)
    output:
        tracks="results/{experiment}/{detector}/{run}/tracks.pkl",
        feather="results/{experiment}/{detector}/{run}/tracks.feather",
        preset="results/{experiment}/{detector}/{run}/tracker.yaml",
    wildcard_constraints:
        experiment=AV2_EXPERIMENTS,
    params:
        config=_track_params,
        base=lambda w: config["tracker_presets"][run_of(w)["preset"]]["base"],
        overrides=lambda w: jq(config["tracker_presets"][run_of(w)["preset"]]["overrides"]),
        tracker=lambda w: run_of(w)["tracker"],
        dataroot=lambda w: dataroot(experiment(w)["dataset"]),
        split=lambda w: experiment(w)["split"],
        rate=lambda w: config["datasets"][experiment(w)["dataset"]]["rate_hz"],
        checkpoint=_checkpoint_arg,
        device=config["tracking"]["device"],
        code=code_version("track_av2"),
    log: "logs/track/{experiment}/{detector}/{run}.log"
    benchmark: "logs/benchmarks/track/{experiment}/{detector}/{run}.tsv"
    shell:
        "( {GRUTRACK} resolve-config tracker --base {params.base} --overrides {params.overrides:q} "
        "--out {output.preset} && "
        "{GRUTRACK} track --dataset av2 --dataroot {params.dataroot:q} --split {params.split} --rate {params.rate} "
        "--detections {input.detections} --tracker {params.tracker} --config {output.preset} "
        "{params.checkpoint} --device {params.device} --out {output.tracks} "
        "--no-progress ) > {log} 2>&1 " + ON_FAIL
