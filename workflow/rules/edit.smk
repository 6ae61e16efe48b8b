rule edit:
    """The scene's edits (relight, insert, repaint, novel camera; docs/edit.md), each rendered
    with the recovered scene, and with the truth beside it for a synthetic scene."""
    input:
        scene="results/{scene}/scene",
        truth=edit_truth,
    output:
        report(
            directory("results/{scene}/edits"),
            patterns=["{edit}/{view}.png"],
            caption="../report/edits.rst",
            category="Edits",
            subcategory="{scene}",
            labels={"scene": "{scene}", "edit": "{edit}", "view": "{view}"},
        ),
    log:
        "results/{scene}/logs/edit.log",
    benchmark:
        "results/{scene}/benchmarks/edit.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=gpu_request,
    params:
        edits=lambda wildcards: json.dumps(SCENES[wildcards.scene]["edits"]),
        truth=edit_truth_option,
        spp=config["edit"]["spp"],
        seed=config["edit"]["seed"],
        device=device_option,
    shell:
        "printf '%s\\n' {params.edits:q} | invrender --log {log} edit --scene {input.scene}"
        " --edits /dev/stdin --out {output} {params.truth} --spp {params.spp} --seed {params.seed}"
        " {params.device}"
