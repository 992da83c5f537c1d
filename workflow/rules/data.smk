# Stage "data": the embedded SYNTHETIC demo dataset (nuScenes table format, custom splits demo_train / demo_val).
# Real datasets (nuScenes, AV2) are the user's; their dataroots are config values, never written.

DEMO = {n: d for n, d in config["datasets"].items() if d["kind"] == "demo"}


def _demo_dataset(w):
    """The demo dataset whose dataroot/version the output path names."""
    for name, ds in DEMO.items():
        if ds["dataroot"] == w.demo_root and ds["version"] == w.demo_version:
            return ds
    raise WorkflowError(f"no demo dataset with dataroot {w.demo_root} and version {w.demo_version}")


rule demo_data:
    output:
        scene="{demo_root}/{demo_version}/scene.json",
        splits="{demo_root}/{demo_version}/splits.json",
    wildcard_constraints:
        demo_root=_alternation(d["dataroot"] for d in DEMO.values()),
        demo_version=_alternation(d["version"] for d in DEMO.values()),
    params:
        dataset=lambda w: jq(_demo_dataset(w)),
        scenes=lambda w: _demo_dataset(w)["scenes"],
        frames=lambda w: _demo_dataset(w)["frames_per_scene"],
        seed=lambda w: _demo_dataset(w)["seed"],
        code=code_version("data"),
    log: "logs/data/{demo_root}/{demo_version}.log"
    benchmark: "logs/benchmarks/data/{demo_root}/{demo_version}.tsv"
    shell:
        "{GRUTRACK} demo-data --out {wildcards.demo_root} --version {wildcards.demo_version} "
        "--scenes {params.scenes} --frames-per-scene {params.frames} --seed {params.seed} > {log} 2>&1 " + ON_FAIL
