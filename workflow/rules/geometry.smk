rule geometry:
    """The capture's mesh (or point cloud) cleaned, simplified and unwrapped: mesh.ply,
    atlas.npz (xatlas UVs, texel -> surface point and normal) and geometry.json."""
    input:
        mesh=geometry_mesh_input,
    output:
        report(
            directory("results/{scene}/geometry"),
            patterns=["{name}.json"],
            caption="../report/geometry.rst",
            category="Geometry",
            labels={"scene": "{scene}", "file": "{name}.json"},
        ),
    log:
        "results/{scene}/logs/geometry.log",
    benchmark:
        "results/{scene}/benchmarks/geometry.tsv"
    conda:
        "../../envs/geometry.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=30,
    params:
        mesh=geometry_mesh,
        options=geometry_options,
    shell:
        "invrender --log {log} geometry {params.mesh:q} --out {output} {params.options}"
        " --threads {threads}"
