rule cameras:
    """The capture's cameras (COLMAP model, text or binary, or transforms.json), read by the one
    loader and written back as a COLMAP text model, with images/: each camera's image, checked
    (size, finite pixels) and linked, or for a panorama its six cube faces. What every later
    stage reads. A duplicates or room capture's one photograph: the folder it is in is the images
    folder, or with a lens (no model) it is the source."""
    input:
        cameras=capture_cameras_input,
        images=capture_images,
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
        mem_mb=3000,
        runtime=10,
    params:
        source=capture_cameras,
        options=cameras_options,
    shell:
        "invrender --log {log} cameras {params.source:q} --out {output} {params.options}"
