# Structure from Duplicates, its poses and shape: per instance, a crop and its features at every rotation
# angle (fanned out from the segment checkpoint's instances.json); then all pairs matched, COLMAP's
# virtual cameras, the visual hull and render-and-compare refinement in one job.


rule duplicates_crop:
    """One instance's crop (fixed size, exact map back to the photograph's pixels) and its
    features at every rotation angle of the search."""
    input:
        segmentation=segmentation_dir,
        cameras="results/{scene}/cameras",
    output:
        crop="results/{scene}/crops/instance_{instance}.npz",
        features="results/{scene}/crops/instance_{instance}.features.npz",
    log:
        "results/{scene}/logs/duplicates_crop/{instance}.log",
    benchmark:
        "results/{scene}/benchmarks/duplicates_crop/{instance}.tsv"
    wildcard_constraints:
        instance=r"\d+",
    group:
        "duplicates_crops"
    conda:
        "../../envs/workflow.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        masks=instance_masks,
        instance=lambda wildcards: int(wildcards.instance),
        settings=duplicates_settings,
    shell:
        "invrender --log {log} duplicates crop --cameras {input.cameras} --masks {params.masks:q}"
        " --instance {params.instance} --crop {output.crop} --features {output.features}"
        " {params.settings}"


rule duplicates:
    """All pairs of crops matched with the rotation search, COLMAP's virtual cameras turned into
    object poses, the shared mesh carved as a visual hull and the poses refined by
    render-and-compare: sparse/, poses.json, object.ply, duplicates.json, overlay.png.
    """
    input:
        segmentation=segmentation_dir,
        cameras="results/{scene}/cameras",
        crops=instance_files(".npz"),
        features=instance_files(".features.npz"),
    output:
        report(
            directory("results/{scene}/duplicates"),
            patterns=["{name}.png"],
            caption="../report/duplicates.rst",
            category="Duplicates",
            labels={"scene": "{scene}", "figure": "{name}"},
        ),
    log:
        "results/{scene}/logs/duplicates.log",
    benchmark:
        "results/{scene}/benchmarks/duplicates.tsv"
    conda:
        "../../envs/workflow.yaml"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    params:
        masks=instance_masks,
        settings=duplicates_settings,
    shell:
        "invrender --log {log} duplicates solve --cameras {input.cameras} --masks {params.masks:q}"
        " --instances {input.segmentation}/instances.json"
        " --crops results/{wildcards.scene}/crops --features results/{wildcards.scene}/crops"
        " --out {output} {params.settings}"
