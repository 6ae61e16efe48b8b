rule gradients:
    """d(image loss)/d(map) of the state an optimiser starts from (the captured geometry with
    uniform maps): one EXR and one signed PNG preview per parameter map, and a report.
    """
    input:
        geometry="results/{scene}/geometry",
        cameras="results/{scene}/cameras",
    output:
        report(
            directory("results/{scene}/gradients"),
            patterns=["{map,[a-z]+}.png"],
            caption="../report/gradients.rst",
            category="Gradients",
            subcategory="{scene}",
            labels={"scene": "{scene}", "map": "{map}"},
        ),
    log:
        "results/{scene}/logs/gradients.log",
    benchmark:
        "results/{scene}/benchmarks/gradients.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=gpu_request,
    params:
        batch=config["gradients"]["batch"],
        spp=config["gradients"]["spp"],
        seed=config["gradients"]["seed"],
        accumulation=config["gradients"]["accumulation"],
        device=device_option,
    shell:
        "invrender --log {log} gradients --geometry {input.geometry} --cameras {input.cameras}"
        " --images {input.cameras}/images --out {output} --batch {params.batch} --spp {params.spp}"
        " --seed {params.seed} --accumulation {params.accumulation} {params.device}"
