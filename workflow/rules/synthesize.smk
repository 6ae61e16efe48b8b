rule synthesize:
    """A parametric scene rendered into a capture (images, COLMAP cameras, mesh.ply; a room
    photo: photo, depth, panoptic segmentation, camera.json), with its ground truth beside it:
    the demo's stand-in for a capture a user brings."""
    output:
        report(
            directory("results/{scene}/capture"),
            # images/: the views of a multiview or duplicates capture; photo.png: a room photo
            patterns=["images/{view,[^/]+}.png", "{view,photo}.png"],
            caption="../report/capture.rst",
            category="Capture",
            subcategory="{scene}",
            labels={"scene": "{scene}", "view": "{view}"},
        ),
    log:
        "results/{scene}/logs/synthesize.log",
    benchmark:
        "results/{scene}/benchmarks/synthesize.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=2000,
        runtime=30,
        gpu=gpu_request,
    params:
        kind=lambda wildcards: SCENES[wildcards.scene]["synthetic"]["kind"],
        spp=lambda wildcards: SCENES[wildcards.scene]["synthetic"]["spp"],
        seed=lambda wildcards: SCENES[wildcards.scene]["synthetic"]["seed"],
        config=synthesize_config,
        device=device_option,
    shell:
        "printf '%s\\n' {params.config:q} | invrender --log {log} synthesize {params.kind}"
        " --out {output} --config /dev/stdin --spp {params.spp} --seed {params.seed}"
        " {params.device}"
