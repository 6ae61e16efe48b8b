rule geometry:
    """The capture's mesh (or point cloud) cleaned, simplified and unwrapped: mesh.ply,
    atlas.npz (xatlas UVs, texel -> surface point and normal) and geometry.json."""
    input:
        mesh=capture_path("mesh.ply"),
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
        mesh=lambda wildcards: os.path.join(capture_dir(wildcards), "mesh.ply"),
        options=geometry_options,
    shell:
        "invrender --log {log} geometry {params.mesh:q} --out {output} {params.options}"
        " --threads {threads}"
