# Stage "detections": simulated detections (demo or any nuScenes-format split with ground truth), and published
# detections from the registry (grutrack/configs/detections.yaml): downloaded, or put in place by hand where
# the host needs a browser, then converted to one split's detections.


def _registry_source(w):
    """Registry name of the detector's source for this split."""
    return config["detectors"][w.detector]["sources"][w.split]


rule simulate_detections:
    input:
        data=lambda w: dataset_input(w.dataset, w.split),
    output: "detections/simulated/{dataset}/{split}/{detector}.json"
    params:
        dataroot=lambda w: dataroot(w.dataset),
        version=lambda w: S.version_for(config, w.dataset, w.split),
        profile=lambda w: config["detectors"][w.detector]["profile"],
        seed=lambda w: config["detectors"][w.detector]["seeds"][w.split],
        code=code_version("simulate"),
    log: "logs/detections/simulate/{dataset}/{split}/{detector}.log"
    benchmark: "logs/benchmarks/detections/simulate/{dataset}/{split}/{detector}.tsv"
    shell:
        "{GRUTRACK} simulate-detections --dataroot {params.dataroot} --version {params.version} "
        "--split {wildcards.split} --profile {params.profile} --seed {params.seed} --out {output} > {log} 2>&1 "
        + ON_FAIL


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
        raw=lambda w: S.raw_source_file(REGISTRY, _registry_source(w)),
        data=lambda w: dataset_input(w.dataset, w.split),
    output: "detections/converted/{dataset}/{split}/{detector}.{ext}"
    wildcard_constraints:
        ext="json|feather",
    params:
        source=_registry_source,
        dataroot=lambda w: dataroot(w.dataset),
        version=lambda w: S.version_for(config, w.dataset, w.split) or "none",
        code=code_version("convert"),
    log: "logs/detections/convert/{dataset}/{split}/{detector}.{ext}.log"
    benchmark: "logs/benchmarks/detections/convert/{dataset}/{split}/{detector}.{ext}.tsv"
    shell:
        "{GRUTRACK} convert-detections {params.source} --raw {input.raw} --dataroot {params.dataroot} "
        "--version {params.version} --split {wildcards.split} --out {output} > {log} 2>&1 " + ON_FAIL
