# Stage "detections": simulated detections (any dataset split with ground truth); published
# detections from the registry (grutrack/configs/detections.yaml), downloaded or put in place by hand where
# the host needs a browser; and the user's own detection files (detector kind local). Published and local
# files are converted to one split's detections (validated against the split).


def _raw_input(w):
    """The file convert_detections reads: a registry download or the user's local file."""
    det = config["detectors"][w.detector]
    if det["kind"] == "local":
        return det["files"][w.split]
    return S.raw_source_file(REGISTRY, det["sources"][w.split])


def _format_args(w):
    """How convert_detections learns the format: the registry source's name, or the local detector's format."""
    det = config["detectors"][w.detector]
    if det["kind"] == "local":
        return f"--format {det['format']}" + (f" --member {shlex.quote(det['member'])}" if det["member"] else "")
    return det["sources"][w.split]


rule simulate_detections:
    input:
        data=lambda w: dataset_input(w.dataset, w.split),
    output: "detections/simulated/{dataset}/{split}/{detector}.{ext}"
    wildcard_constraints:
        ext="json|feather",
    params:
        data=lambda w: S.dataset_args(config, w.dataset, w.split),
        profile=lambda w: config["detectors"][w.detector]["profile"],
        seed=lambda w: config["detectors"][w.detector]["seeds"][w.split],
        code=code_version("simulate"),
    log: "logs/detections/simulate/{dataset}/{split}/{detector}.{ext}.log"
    benchmark: "logs/benchmarks/detections/simulate/{dataset}/{split}/{detector}.{ext}.tsv"
    shell:
        "{GRUTRACK} simulate-detections {params.data} --profile {params.profile} --seed {params.seed} "
        "--out {output} > {log} 2>&1 " + ON_FAIL


rule fetch_detections:
    output: "detections/raw/{source}/{filename}"
    params:
        url=lambda w: REGISTRY[w.source].url,
        sha256=lambda w: REGISTRY[w.source].sha256,
        code=code_version("fetch"),
    log: "logs/detections/fetch/{source}/{filename}.log"
    benchmark: "logs/benchmarks/detections/fetch/{source}/{filename}.tsv"
    shell:
        "{GRUTRACK} download-detections {wildcards.source} --out detections/raw/{wildcards.source} --no-progress "
        "> {log} 2>&1 " + ON_FAIL


rule convert_detections:
    input:
        raw=_raw_input,
        data=lambda w: dataset_input(w.dataset, w.split),
    output: "detections/converted/{dataset}/{split}/{detector}.{ext}"
    wildcard_constraints:
        ext="json|feather",
    params:
        source=_format_args,
        dataroot=lambda w: dataroot(w.dataset),
        version=lambda w: S.version_for(config, w.dataset, w.split) or "none",
        code=code_version("convert"),
    log: "logs/detections/convert/{dataset}/{split}/{detector}.{ext}.log"
    benchmark: "logs/benchmarks/detections/convert/{dataset}/{split}/{detector}.{ext}.tsv"
    shell:
        "{GRUTRACK} convert-detections {params.source} --raw {input.raw:q} --dataroot {params.dataroot:q} "
        "--version {params.version} --split {wildcards.split} --out {output} > {log} 2>&1 " + ON_FAIL
