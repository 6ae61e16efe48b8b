rule render:
    """Every camera of the scene rendered with the scene's features: EXR, PNG preview, and the
    depth, normal, UV, instance and triangle AOVs."""
    input:
        scene="results/{scene}/scene",
        features="results/{scene}/features.json",
    output:
        report(
            directory("results/{scene}/renders"),
            patterns=["{view,[^/]+}.png"],
            caption="../report/renders.rst",
            category="Renders",
            subcategory="{scene}",
            labels={"scene": "{scene}", "view": "{view}"},
        ),
    log:
        "results/{scene}/logs/render.log",
    benchmark:
        "results/{scene}/benchmarks/render.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=gpu_request,
    params:
        spp=config["render"]["spp"],
        seed=config["render"]["seed"],
        device=device_option,
    shell:
        "invrender --log {log} render {input.scene} --features {input.features}"
        " --out {output} --spp {params.spp} --seed {params.seed} {params.device}"
