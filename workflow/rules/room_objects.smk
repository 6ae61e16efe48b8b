"""The room's objects (mode `room`, PSDR-Room section 4.3): each object and lamp
segment of the photograph retrieved from the asset library, placed from its depth points on its
support (the floor or another object), then all refined jointly by the differentiable mask IoU
and depth L1 of Eq. 3, as results/{scene}/room_objects/ (objects.json, room_objects.png). Its
inputs are room_box's and the capture; its input functions are in common.smk
(room_box_input, room_objects_options).
"""


rule room_objects:
    """The objects of a room photograph, retrieved, placed and refined in its room box."""
    input:
        room_box_input,
        room="results/{scene}/room_box",
    output:
        directory("results/{scene}/room_objects"),
    log:
        "results/{scene}/logs/room_objects.log",
    benchmark:
        "results/{scene}/benchmarks/room_objects.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=2000,
        runtime=20,
        gpu=gpu_request,
    params:
        capture=capture_dir,
        options=room_objects_options,
        device=device_option,
    shell:
        "invrender --log {log} room-objects {params.capture:q} --room {input.room:q} --out {output}"
        " {params.options} {params.device}"
