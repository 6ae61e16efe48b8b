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


rule evaluate_duplicates:
    """A recovered duplicates scene against the synthetic truth: mask IoU, instances registered,
    rotation error (a can's twist about its axis apart) and translation error after a similarity
    alignment, before and after render-and-compare, and the shared mesh's Chamfer distance; from
    the recovered scene directory the shared material (albedo PSNR, roughness MSE), the sky (env
    MSE) and relighting under two new skies with the copies rearranged (SfD's Table 1), with the
    material stage's time and memory when its training.json is there.
    """
    input:
        segmentation=segmentation_dir,
        duplicates="results/{scene}/duplicates",
        capture="results/{scene}/capture",
        scene="results/{scene}/scene",
    output:
        report(
            directory("results/{scene}/report"),
            patterns=["{figure}.png"],
            caption="../report/report_duplicates.rst",
            category="Evaluation",
            subcategory="{scene}",
            labels={"scene": "{scene}", "figure": "{figure}"},
        ),
    log:
        "results/{scene}/logs/evaluate.log",
    benchmark:
        "results/{scene}/benchmarks/evaluate_duplicates.tsv"
    wildcard_constraints:
        scene=scenes_pattern([name for name in DUPLICATES if name in SYNTHETIC]),
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=gpu_request,
    params:
        seed=config["evaluate"]["seed"],
        spp=config["evaluate"]["spp"],
        device=device_option,
        training="results/{scene}/material/training.json",
    shell:
        "invrender --log {log} evaluate --duplicates {input.duplicates}"
        " --segmentation {input.segmentation} --truth {input.capture}/ground_truth"
        " --images {input.capture}/images --scene {input.scene} --training {params.training}"
        " --out {output} --seed {params.seed} --spp {params.spp} {params.device}"


rule evaluate_room:
    """A room scene against the synthetic truth of its photo: the photo re-rendered (PSNR, SSIM),
    mask IoU per class, the room box's corner error, the objects' errors (room_objects' metrics,
    when that stage is there), the lights' total power and the material on the surface
    (workflow/invrender/evaluate/room.py)."""
    input:
        unpack(room_evaluate_inputs),
    output:
        report(
            directory("results/{scene}/report"),
            patterns=["{figure}.png"],
            caption="../report/report_room.rst",
            category="Evaluation",
            subcategory="{scene}",
            labels={"scene": "{scene}", "figure": "{figure}"},
        ),
    log:
        "results/{scene}/logs/evaluate.log",
    benchmark:
        "results/{scene}/benchmarks/evaluate_room.tsv"
    wildcard_constraints:
        scene=scenes_pattern([name for name in ROOM if name in SYNTHETIC]),
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=gpu_request,
    params:
        options=room_evaluate_options,
        spp=config["evaluate"]["spp"],
        seed=config["evaluate"]["seed"],
        device=device_option,
    shell:
        "invrender --log {log} evaluate --room {input.room:q} --scene {input.scene}"
        " --capture {input.capture} --truth {input.capture}/truth --out {output}"
        " {params.options} --spp {params.spp} --seed {params.seed} {params.device}"
