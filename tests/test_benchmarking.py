import json

from ilfo.benchmarking import machine, print_rows


def test_print_rows_as_a_table_and_as_json(capsys):
    rows = [{"n": 1000, "ms": 2.345}, {"n": 20, "ms": 0.5}]
    print_rows(rows, {"n": "{n:,}", "ms per solve": "{ms:.1f}"}, as_json=False)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].endswith(machine())
    assert lines[1:] == ["| n | ms per solve |", "|---|---|", "| 1,000 | 2.3 |", "| 20 | 0.5 |"]
    print_rows(rows, {"n": "{n}"}, as_json=True)
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["ms"] for r in records] == [2.345, 0.5]
    assert all(r["machine"] == machine() and r["date"] for r in records)
