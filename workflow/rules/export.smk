rule export:
    """The scene as USD for other tools: scene.usda (and scene.usdc on request) with textures/,
    meshes, UsdPreviewSurface materials, UsdLux lights, cameras and native instancing of
    duplicates, checked by the validators usdchecker runs; export.json summarises it."""
    input:
        scene="results/{scene}/scene",
    output:
        report(
            directory("results/{scene}/export"),
            patterns=["{name}.json"],
            caption="../report/export.rst",
            category="Export",
            labels={"scene": "{scene}", "file": "{name}.json"},
        ),
    log:
        "results/{scene}/logs/export.log",
    benchmark:
        "results/{scene}/benchmarks/export.tsv"
    conda:
        "../../envs/workflow.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        options=export_options,
    shell:
        "invrender --log {log} export {input.scene} --out {output} {params.options}"
