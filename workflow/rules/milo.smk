rule milo_train:
    """MILO-Net trained on the capture through the adjoint path tracer (MILO sections 3.3-3.5):
    the network, the maps it predicts, a row of losses and timings per iteration, snapshots of the
    maps for the accuracy-against-time curve. Checkpoints stay in milo/checkpoints/ (not an
    output, so a job stopped by a time limit resumes: config milo.resume)."""
    input:
        geometry="results/{scene}/geometry",
        cameras="results/{scene}/cameras",
    output:
        weights="results/{scene}/milo/weights.pt",
        maps="results/{scene}/milo/maps.npz",
        log_csv=report(
            "results/{scene}/milo/log.csv",
            caption="../report/milo.rst",
            category="MILO-Net",
            labels={"scene": "{scene}", "file": "log.csv"},
        ),
        training="results/{scene}/milo/training.json",
    log:
        "results/{scene}/logs/milo_train.log",
    benchmark:
        "results/{scene}/benchmarks/milo_train.tsv"
    wildcard_constraints:
        scene=scenes_pattern(MULTIVIEW),
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=8000,
        runtime=milo_runtime,
        gpu=gpu_request,
    params:
        out="results/{scene}/milo",
        preset=config["milo"]["preset"],
        settings=milo_settings,
        resume=config["milo"]["resume"],
        device=device_option,
    shell:
        "invrender --log {log} milo --geometry {input.geometry} --cameras {input.cameras}"
        " --images {input.cameras}/images --out {params.out} --preset {params.preset}"
        " {params.settings} --resume {params.resume} {params.device}"
