rule bake:
    """The recovered scene directory: MILO-Net's maps on the geometry stage's mesh and atlas, seen
    by the capture's cameras; what features, render, export, evaluate and edit read."""
    input:
        maps="results/{scene}/milo/maps.npz",
        training="results/{scene}/milo/training.json",
        geometry="results/{scene}/geometry",
        cameras="results/{scene}/cameras",
    output:
        report(
            directory("results/{scene}/scene"),
            patterns=["{name}.json"],
            caption="../report/bake.rst",
            category="Scene",
            labels={"scene": "{scene}", "file": "{name}.json"},
        ),
    log:
        "results/{scene}/logs/bake.log",
    benchmark:
        "results/{scene}/benchmarks/bake.tsv"
    wildcard_constraints:
        scene=scenes_pattern(MULTIVIEW),
    conda:
        "../../envs/render.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    shell:
        "invrender --log {log} bake --maps {input.maps} --training {input.training}"
        " --geometry {input.geometry} --cameras {input.cameras} --out {output}"


rule bake_duplicates:
    """A duplicates scene directory: the shared mesh (geometry stage) instanced at every recovered
    pose (duplicates stage), seen by the photograph's camera, with the shared material, the sky
    and the support surface the material stage recovered (duplicates_material)."""
    input:
        geometry="results/{scene}/geometry",
        duplicates="results/{scene}/duplicates",
        cameras="results/{scene}/cameras",
        segmentation=segmentation_dir,
        material="results/{scene}/material/maps.npz",
        training="results/{scene}/material/training.json",
    output:
        report(
            directory("results/{scene}/scene"),
            patterns=["{name}.json"],
            caption="../report/bake.rst",
            category="Scene",
            labels={"scene": "{scene}", "file": "{name}.json"},
        ),
    log:
        "results/{scene}/logs/bake.log",
    benchmark:
        "results/{scene}/benchmarks/bake_duplicates.tsv"
    wildcard_constraints:
        scene=scenes_pattern(DUPLICATES),
    conda:
        "../../envs/render.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        masks=instance_masks,
    shell:
        "invrender --log {log} bake --poses {input.duplicates}/poses.json --masks {params.masks:q}"
        " --material results/{wildcards.scene}/material"
        " --geometry {input.geometry} --cameras {input.cameras} --out {output}"


rule bake_room:
    """A room scene directory (mode room): the room box as inward-facing walls, floor
    and ceiling, the room_lights stage's lights as one-sided emitters, and, where those stages
    exist, the room_objects stage's placed assets and the room_materials stage's materials,
    seen by the photo's camera (workflow/invrender/bake/room.py)."""
    input:
        unpack(room_scene_inputs),
    output:
        report(
            directory("results/{scene}/scene"),
            patterns=["{name}.json"],
            caption="../report/bake.rst",
            category="Scene",
            labels={"scene": "{scene}", "file": "{name}.json"},
        ),
    log:
        "results/{scene}/logs/bake.log",
    benchmark:
        "results/{scene}/benchmarks/bake_room.tsv"
    wildcard_constraints:
        scene=scenes_pattern(ROOM),
    conda:
        "../../envs/render.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        capture=capture_dir,
        options=bake_room_options,
    shell:
        "invrender --log {log} bake --room {input.room:q} --out {output} {params.options}"
