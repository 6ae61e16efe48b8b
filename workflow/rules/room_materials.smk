"""The room's materials and lights (mode `room`, PSDR-Room section 4.4): crop
pairs, homogeneous albedos from shading-corrected median colours, procedural retrieval with the
transform search, then Eq. 4's joint optimisation of materials (through the adjoint) and light
radiances (exact per-light NNLS), as results/{scene}/room_materials/ (materials.json, lights.json,
thumbnails.png, room_materials.png; docs/room-materials.md). Its input functions are in common.smk
(room_materials_inputs, room_materials_options): room_objects is taken when its rule is part of
the workflow, as bake_room does.
"""


rule room_materials:
    """The materials of the room's parts and the radiances of its lights, fitted to the photo."""
    input:
        unpack(room_materials_inputs),
    output:
        directory("results/{scene}/room_materials"),
    log:
        "results/{scene}/logs/room_materials.log",
    benchmark:
        "results/{scene}/benchmarks/room_materials.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=3000,
        runtime=30,
        gpu=gpu_request,
    params:
        capture=capture_dir,
        options=room_materials_options,
        device=device_option,
    shell:
        "invrender --log {log} room-materials {params.capture:q} --room {input.room:q}"
        " --lights {input.lights:q} --out {output} {params.options} {params.device}"
