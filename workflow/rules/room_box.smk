"""The room box (mode `room`, PSDR-Room section 4.2): the room as a box from one
photograph's depth, wall/floor/ceiling segmentation and field of view, as
results/{scene}/room_box/ (room.json: the box, the camera, the floor, the coarse box, the
losses and the metrics; room_box.png), built by `all` for every room scene (the light, object
and material stages start from it). Its input functions are in common.smk,
"room".
"""


rule room_box:
    """The room box of a room photograph: the coarse fit (RANSAC floor, height, walls) refined
    by the differentiable mask IoU and depth L1 of PSDR-Room's Eq. 2."""
    input:
        room_box_input,
    output:
        report(
            directory("results/{scene}/room_box"),
            patterns=["{name}.png"],
            caption="../report/room_box.rst",
            category="Room",
            labels={"scene": "{scene}", "figure": "{name}"},
        ),
    log:
        "results/{scene}/logs/room_box.log",
    benchmark:
        "results/{scene}/benchmarks/room_box.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=2000,
        runtime=15,
    params:
        capture=capture_dir,
        options=room_box_options,
    shell:
        "invrender --log {log} room-box {params.capture:q} --out {output} {params.options}"
