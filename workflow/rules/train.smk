# Stage "train": the GRU-Kalman filter, semi-supervised (or supervised) on a training split. The training config
# is the shipped one with the workflow's overrides, resolved and validated into checkpoints/<name>/training.yaml.


def _training(w):
    return config["trainings"][w.training]


def _train_inputs(w):
    tr = _training(w)
    out = {"data": dataset_input(tr["dataset"], tr["split"]),
           "detections": S.detections_file(config, tr["dataset"], tr["split"], tr["detector"])}
    if tr["validation"]:
        out["val_detections"] = S.detections_file(config, tr["dataset"], tr["validation"]["split"], tr["detector"])
    return out


def _val_args(w, input):
    tr = _training(w)
    if not tr["validation"]:
        return ""
    return (f"--val-split {tr['validation']['split']} --val-detections {input.val_detections} "
            f"--val-every {tr['validation']['every']}")


rule train:
    input: unpack(_train_inputs)
    output:
        model="checkpoints/{training}/model.pt",
        log_csv="checkpoints/{training}/train_log.csv",
        config="checkpoints/{training}/training.yaml",
        validation="checkpoints/{training}/validation.json",
    params:
        training=lambda w: jq(_training(w)),
        base=lambda w: _training(w)["config"],
        overrides=lambda w: jq(_training(w)["overrides"]),
        data=lambda w: S.dataset_args(config, _training(w)["dataset"], _training(w)["split"]),
        val=_val_args,
        code=code_version("train"),
    threads: 1          # one intra-op thread: fastest alone and side by side (docs/results/threads.md)
    priority: 10        # the longest jobs of a DAG: started first, side by side, with the short jobs around them
    log: "logs/train/{training}.log"
    benchmark: "logs/benchmarks/train/{training}.tsv"
    shell:
        "( {GRUTRACK} resolve-config training --base {params.base} --overrides {params.overrides:q} "
        "--out {output.config} && "
        "{GRUTRACK} train {params.data} "
        "--detections {input.detections} --config {output.config} --out checkpoints/{wildcards.training} "
        "{params.val} --no-progress ) > {log} 2>&1 " + ON_FAIL


rule package_pretrained:
    """A training packaged as a pretrained network (model.pt without its resume state, config, log, validation
    record, provenance.json): `bash scripts/pretrain_grukf.sh` builds pretrained/grukf_default with
    workflow/config/mini.yaml and copies it into grutrack/pretrained/."""
    input:
        model="checkpoints/{training}/model.pt",
        log_csv="checkpoints/{training}/train_log.csv",
        config="checkpoints/{training}/training.yaml",
        validation="checkpoints/{training}/validation.json",
        detections=lambda w: S.detections_file(config, _training(w)["dataset"], _training(w)["split"],
                                               _training(w)["detector"]),
    output:
        model="pretrained/{training}/model.pt",
        provenance="pretrained/{training}/provenance.json",
    log: "logs/train/{training}.pretrained.log"
    shell:
        "{PY} -m grutrack.training.pretrained --from checkpoints/{wildcards.training} "
        "--detections {input.detections} --out pretrained/{wildcards.training} "
        "--command 'bash scripts/pretrain_grukf.sh' > {log} 2>&1 " + ON_FAIL
