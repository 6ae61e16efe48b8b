"""Reading the benchmarks' markdown tables back in their tests."""


def tables(markdown: str) -> dict:
    """{section title: [{column header: cell}]} of every table in milo.md."""
    found = {}
    for section in markdown.split("\n### ")[1:]:
        title, _, body = section.partition("\n\n")
        lines = [line for line in body.splitlines() if line.startswith("|")]
        cells = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines]
        found[title] = [dict(zip(cells[0], row)) for row in cells[2:]]
    return found


def printed(cell: str, value: float, fmt: str) -> bool:
    """`cell` is `value` printed with `fmt` (.Nf or .Ng)."""
    digits, kind = int(fmt[1:-1]), fmt[-1]
    tolerance = 0.5 * 10**-digits if kind == "f" else 0.5 * 10 ** (1 - digits) * abs(value)
    return abs(float(cell) - value) <= tolerance * (1 + 1e-9)
