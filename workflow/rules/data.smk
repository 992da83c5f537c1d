# Stage "data": the embedded SYNTHETIC demo dataset (nuScenes table format, custom splits demo_train / demo_val).
# Real datasets (nuScenes, AV2) are the user's; their dataroots are config values, never written.

DEMO = {n: d for n, d in config["datasets"].items() if d["kind"] == "demo"}


def _demo_dataset(w):
    """The demo dataset whose dataroot the output names."""
    for name, ds in DEMO.items():
        if ds["dataroot"] == w.demo_root:
            return ds
    raise WorkflowError(f"no demo dataset with dataroot {w.demo_root}")


rule demo_data:
    output: directory("{demo_root}")
    wildcard_constraints:
        demo_root=_alternation(d["dataroot"] for d in DEMO.values()),
    params:
        dataset=lambda w: jq(_demo_dataset(w)),
        scenes=lambda w: _demo_dataset(w)["scenes"],
        frames=lambda w: _demo_dataset(w)["frames_per_scene"],
        seed=lambda w: _demo_dataset(w)["seed"],
        version=lambda w: _demo_dataset(w)["version"],
        code=code_version("data"),
    log: "logs/data/{demo_root}.log"
    benchmark: "logs/benchmarks/data/{demo_root}.tsv"
    shell:
        "{GRUTRACK} demo-data --out {output} --version {params.version} "
        "--scenes {params.scenes} --frames-per-scene {params.frames} --seed {params.seed} > {log} 2>&1 " + ON_FAIL
