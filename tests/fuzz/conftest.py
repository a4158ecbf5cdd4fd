"""Fuzz tests: print how many cases each test ran at the end of the session."""
from __future__ import annotations

import fuzzlib


def pytest_terminal_summary(terminalreporter) -> None:
    if not fuzzlib.CASES:
        return
    total = sum(fuzzlib.CASES.values())
    terminalreporter.section("fuzz cases")
    for name, n in sorted(fuzzlib.CASES.items()):
        terminalreporter.write_line(f"{name}: {n}")
    terminalreporter.write_line(f"fuzz_cases_total={total}")
