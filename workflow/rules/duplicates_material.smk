# Structure from Duplicates, its appearance: the copies' one shared material, their support's and the
# sky, from the photograph through the adjoint path tracer; bake_duplicates then writes the scene.


rule duplicates_material:
    """kd, ks, ka of the shared atlas (and of the support plane) and the sky kg, optimised on the
    masked pixels of the photograph: maps.npz, support/, log.csv, training.json, figure.png
    (photograph, re-render, recovered kd). Checkpoints stay in material/checkpoints/ (not an
    output, so a stopped job resumes: config duplicates_material.resume)."""
    input:
        geometry="results/{scene}/geometry",
        duplicates="results/{scene}/duplicates",
        cameras="results/{scene}/cameras",
        segmentation=segmentation_dir,
    output:
        maps="results/{scene}/material/maps.npz",
        log_csv="results/{scene}/material/log.csv",
        training="results/{scene}/material/training.json",
        figure=report(
            "results/{scene}/material/figure.png",
            caption="../report/duplicates_material.rst",
            category="Duplicates",
            labels={"scene": "{scene}", "figure": "material"},
        ),
    log:
        "results/{scene}/logs/duplicates_material.log",
    benchmark:
        "results/{scene}/benchmarks/duplicates_material.tsv"
    wildcard_constraints:
        scene=scenes_pattern(DUPLICATES),
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=material_runtime,
        gpu=gpu_request,
    params:
        out="results/{scene}/material",
        masks=instance_masks,
        preset=config["duplicates_material"]["preset"],
        settings=material_settings,
        resume=config["duplicates_material"]["resume"],
        device=device_option,
    shell:
        "invrender --log {log} duplicates-material --geometry {input.geometry}"
        " --poses {input.duplicates}/poses.json --cameras {input.cameras} --masks {params.masks:q}"
        " --out {params.out} --preset {params.preset} {params.settings} --resume {params.resume}"
        " {params.device}"
