rule features:
    """Which effects the scene calls for (specular lobe, emission, environment, bounce count):
    the kernels' build flags, with the evidence behind each choice."""
    input:
        "results/{scene}/scene",
    output:
        report(
            "results/{scene}/features.json",
            caption="../report/features.rst",
            category="Features",
            labels={"scene": "{scene}"},
        ),
    log:
        "results/{scene}/logs/features.log",
    benchmark:
        "results/{scene}/benchmarks/features.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=2000,
        runtime=10,
        gpu=gpu_request,
    params:
        analysis=analysis_options,
        overrides=feature_overrides,
        device=device_option,
    shell:
        "invrender --log {log} features {input} --out {output} {params.analysis}"
        " {params.overrides} {params.device}"
