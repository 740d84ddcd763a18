"""The bad-input catalogue (tests/fault_catalogue.py): every entry -- a bad case file, override,
option, size, folder or reference, for every command -- ends in one clear line and the documented
exit code, with nothing left behind.  Each runs in a forked child with a memory and a time limit,
so an input that made flexmech allocate without bound or hang fails here instead of taking the suite
with it."""

import pytest

import fault_catalogue as fc


@pytest.fixture(scope="module", autouse=True)
def _template(tmp_path_factory):
    fc.preload(tmp_path_factory.mktemp("catalogue"))


@pytest.mark.parametrize("entry", [e for e in fc.ENTRIES if fc.applicable(e)], ids=lambda e: e.name)
def test_bad_input_ends_in_one_clear_line(entry, tmp_path):
    o = fc.run_entry(entry, tmp_path)
    assert o.verdict == "clean", f"{o.verdict}: {o.why}"
