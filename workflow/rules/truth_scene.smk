# Stands in for the stages that recover a duplicates or room scene (issues 13 and 16) until they
# land: the synthetic scene's ground truth, copied to where those stages will write. A multiview
# scene's directory is recovered (milo_train, bake). features, render and export read
# results/{scene}/scene/ whichever rule made it; a capture of the user's own has no truth, so
# asking for its scene directory stops with a message (synthetic_capture).
rule truth_scene:
    """A synthetic scene's ground truth as its scene directory: a copy of ground_truth/scene/
    (scene.json and the maps), plus the true poses of a duplicates scene's copies (poses.json),
    standing in for the recovering stages of those modes until they land."""
    input:
        synthetic_capture,
    output:
        report(
            directory("results/{scene}/scene"),
            patterns=["{name}.json"],
            caption="../report/truth_scene.rst",
            category="Scene",
            labels={"scene": "{scene}", "file": "{name}.json"},
        ),
    log:
        "results/{scene}/logs/truth_scene.log",
    benchmark:
        "results/{scene}/benchmarks/truth_scene.tsv"
    wildcard_constraints:
        scene=scenes_pattern([name for name in SCENES if name not in MULTIVIEW]),
    conda:
        "../../envs/workflow.yaml"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    params:
        files=truth_files,
    shell:
        "mkdir -p {output} && cp -Rv {params.files:q} {output}/ > {log} 2>&1"
