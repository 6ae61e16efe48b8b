"""The room's initial lights (mode `room`, PSDR-Room section 4.4 "Light
initialization"): the ceiling grid scaled 0.8 less the cells in the camera's frustum or behind
it, a light behind the camera, one per invisible wall, the visible windows, the lamps marked, and
their radiance from one unit-radiance render, as results/{scene}/room_lights/ (lights.json,
room_lights.png). Its inputs are room_box's and the capture; its input functions are in
common.smk (room_box_input, room_lights_options).
"""


rule room_lights:
    """The initial lights of a room photograph on its room box, and their radiance."""
    input:
        room_box_input,
        room="results/{scene}/room_box",
    output:
        directory("results/{scene}/room_lights"),
    log:
        "results/{scene}/logs/room_lights.log",
    benchmark:
        "results/{scene}/benchmarks/room_lights.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=2000,
        runtime=10,
        gpu=gpu_request,
    params:
        capture=capture_dir,
        options=room_lights_options,
        device=device_option,
    shell:
        "invrender --log {log} room-lights {params.capture:q} --room {input.room:q} --out {output}"
        " {params.options} {params.device}"
