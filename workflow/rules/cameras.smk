rule cameras:
    """The capture's cameras (COLMAP model, text or binary, or transforms.json), read by the one
    loader and written back as a COLMAP text model: what every later stage reads."""
    input:
        capture_cameras_input,
    output:
        directory("results/{scene}/cameras"),
    log:
        "results/{scene}/logs/cameras.log",
    benchmark:
        "results/{scene}/benchmarks/cameras.tsv"
    conda:
        "../../envs/geometry.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        source=capture_cameras,
    shell:
        "invrender --log {log} cameras {params.source:q} --out {output}"
