rule evaluate:
    """The recovered scene against the synthetic truth: the maps on the surface (light maps and
    shading-ball material MSE), novel views held out of training, virtual object insertion
    (the paper's Table 3), and the same map errors against training time."""
    input:
        scene="results/{scene}/scene",
        capture="results/{scene}/capture",
        geometry="results/{scene}/geometry",
        cameras="results/{scene}/cameras",
        training="results/{scene}/milo/training.json",
    output:
        report(
            directory("results/{scene}/report"),
            patterns=["{figure}.png"],
            caption="../report/report.rst",
            category="Evaluation",
            subcategory="{scene}",
            labels={"scene": "{scene}", "figure": "{figure}"},
        ),
    log:
        "results/{scene}/logs/evaluate.log",
    benchmark:
        "results/{scene}/benchmarks/evaluate.tsv"
    wildcard_constraints:
        scene=scenes_pattern([name for name in MULTIVIEW if name in SYNTHETIC]),
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=gpu_request,
    params:
        holdout=holdout_options,
        spp=config["evaluate"]["spp"],
        seed=config["evaluate"]["seed"],
        device=device_option,
    shell:
        "invrender --log {log} evaluate --scene {input.scene} --truth {input.capture}/ground_truth/scene"
        " --atlas {input.geometry}/atlas.npz --images {input.cameras}/images --out {output}"
        " --snapshots results/{wildcards.scene}/milo/snapshots {params.holdout}"
        " --spp {params.spp} --seed {params.seed} {params.device}"
