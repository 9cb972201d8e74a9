"""strict_json reads what ``json.loads`` reads, in every encoding it reads, and refuses what
the project's files must not carry."""

from __future__ import annotations

import codecs
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from exohil.formats import strict_json

MAX_INT = 2**63 - 1
json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-MAX_INT, MAX_INT)
    | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner,
                                                                max_size=4),
    max_leaves=12,
)
ENCODINGS = ["utf-8", "utf-8-sig", "utf-16", "utf-16-le", "utf-16-be", "utf-32", "utf-32-le",
             "utf-32-be"]


@given(value=json_values, encoding=st.sampled_from(ENCODINGS))
def test_reads_bytes_in_any_encoding_as_json_loads_does(value: object, encoding: str) -> None:
    data = json.dumps(value, ensure_ascii=False).encode(encoding, "surrogatepass")
    assert strict_json.loads(data) == json.loads(data)
    assert strict_json.loads(bytearray(data)) == json.loads(data)


@given(value=json_values)
def test_reads_text_as_json_loads_does(value: object) -> None:
    text = json.dumps(value, ensure_ascii=False)
    assert strict_json.loads(text) == json.loads(text)


@pytest.mark.parametrize(("data", "problem"), [
    (b"[1, NaN]", "NaN is not a finite number"),
    (b'{"a": -Infinity}', "-Infinity is not a finite number"),
    (b"[1e999]", "number 1e999 is out of range"),
    (b"[" + b"9" * 30 + b"]", "is out of range"),
    (str(MAX_INT + 1).encode(), "is out of range"),
    (b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
    (b"\xff\xfe{", None),  # a UTF-16 byte-order mark before bytes that are not UTF-16 JSON
    (b"{\xff}", None),  # not UTF-8
    (codecs.BOM_UTF8.decode("utf-8") + "[1]", "BOM"),  # text that still has its mark
])
def test_refuses_what_the_files_must_not_carry(data: bytes | str, problem: str | None) -> None:
    with pytest.raises(ValueError, match=problem):
        strict_json.loads(data)
