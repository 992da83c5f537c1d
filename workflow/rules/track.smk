# Stage "track": one job per (experiment, detector, run), for every dataset (the dataset's submission format:
# tracks.json for nuScenes, tracks.pkl for AV2). The tracker preset is the shipped one with the workflow's
# overrides, resolved and validated into results/<experiment>/<detector>/<run>/tracker.yaml first.


def _preset(w):
    return config["tracker_presets"][run_of(w)["preset"]]


def _track_inputs(w):
    exp, run = experiment(w), run_of(w)
    out = {"data": dataset_input(exp["dataset"], exp["split"]),
           "preset": f"results/{w.experiment}/{w.detector}/{w.run}/tracker.yaml",
           "detections": S.detections_file(config, exp["dataset"], exp["split"], w.detector)}
    if run["training"]:
        out["checkpoint"] = S.checkpoint_file(config, run["training"])
    return out


def _track_params(w):
    """Everything the tracking job reads from the config, as one value (Snakemake re-runs when it changes)."""
    exp, run = experiment(w), run_of(w)
    return jq({"data": S.dataset_args(config, exp["dataset"], exp["split"]), "detector": w.detector,
               "run": run, "device": config["tracking"]["device"]})


def _checkpoint_arg(w, input):
    return f"--checkpoint {input.checkpoint}" if run_of(w)["training"] else ""


rule resolve_tracker:
    output: "results/{experiment}/{detector}/{run}/tracker.yaml"
    params:
        preset=lambda w: jq(_preset(w)),
        base=lambda w: _preset(w)["base"],
        overrides=lambda w: jq(_preset(w)["overrides"]),
        code=code_version("resolve"),
    log: "logs/track/{experiment}/{detector}/{run}.resolve.log"
    shell:
        "{GRUTRACK} resolve-config tracker --base {params.base} --overrides {params.overrides:q} --out {output} "
        "> {log} 2>&1 " + ON_FAIL


rule track:
    input: unpack(_track_inputs)
    output: "results/{experiment}/{detector}/{run}/tracks.{ext}"
    wildcard_constraints:
        ext="json|pkl",
    params:
        config=_track_params,
        data=lambda w: S.dataset_args(config, experiment(w)["dataset"], experiment(w)["split"]),
        tracker=lambda w: run_of(w)["tracker"],
        checkpoint=_checkpoint_arg,
        device=config["tracking"]["device"],
        code=code_version("track"),
    log: "logs/track/{experiment}/{detector}/{run}.{ext}.log"
    benchmark: "logs/benchmarks/track/{experiment}/{detector}/{run}.{ext}.tsv"
    shell:
        "{GRUTRACK} track {params.data} --detections {input.detections} --tracker {params.tracker} "
        "--config {input.preset} {params.checkpoint} --device {params.device} --out {output} --config-out none "
        "--no-progress "
        "> {log} 2>&1 " + ON_FAIL
