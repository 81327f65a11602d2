# lidef.parameters() and **params: every row of the table by its name.
import numpy as np
import pytest

import lidef
from conftest import BEAM_BEND


def test_the_table_lists_name_default_range_and_help():
    rows = lidef.parameters()
    by_name = {r["name"]: r for r in rows}
    assert len(by_name) == len(rows) > 30
    assert by_name["lambda_p2p"]["default"] == 1e5
    assert by_name["reduced_dof"]["default"] == 300
    assert by_name["continuation"]["default"] is True
    assert {"first", "third"} <= set(by_name["bound"]["range"])
    lo, hi = by_name["lambda_smooth"]["range"]
    assert lo <= 0.1 <= hi
    for r in rows:
        assert r["help"] and r["group"]


def test_every_row_is_accepted_by_name_with_its_default(beam):
    # Each keyword reaches the parameter table before the arrays are looked at: with a wrong Y the error is
    # about Y, never about the parameter.
    for r in lidef.parameters():
        with pytest.raises(lidef.InputError, match="^Y: "):
            lidef.certify(beam, np.zeros((1, 3)), **{r["name"]: r["default"]})


def test_out_of_range_values_name_the_parameter(beam):
    for r in lidef.parameters():
        if isinstance(r["range"], tuple) and np.isfinite(r["range"][1]) and not isinstance(r["default"], bool):
            with pytest.raises(lidef.InputError, match="^" + r["name"] + ": "):
                lidef.certify(beam, beam.identity(), **{r["name"]: r["range"][1] * 2 + 1})


def test_read_scenario(tmp_path):
    sc = lidef.read_scenario(str(BEAM_BEND))
    assert sc.name == "beam_bend"
    assert sc.sources.shape == sc.targets.shape == (10, 3)
    assert sc.parameters == {}
    with pytest.raises(lidef.InputError, match="nothing.json"):
        lidef.read_scenario(str(tmp_path / "nothing.json"))
    bad = tmp_path / "bad.json"
    bad.write_text('{"model": "beam", "handels": []}')
    with pytest.raises(lidef.InputError, match="bad.json"):
        lidef.read_scenario(str(bad))
