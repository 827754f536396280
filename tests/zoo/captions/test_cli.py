"""`zoo captions list|paraphrase` in-process, and the paraphrase prompt round trip (no network)."""

from __future__ import annotations

import json

import pytest

from zoo.captions.cli import build_paraphrase_prompt, parse_paraphrase_reply
from zoo.cli import main


def test_list_json_has_every_caption_and_field(capsys):
    assert main(["captions", "list", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 61
    for row in rows:
        assert {"caption", "rule", "category", "paraphrases"} <= set(row)
        assert len(row["paraphrases"]) >= 40
    assert {r["category"] for r in rows} == {"achievement", "movement", "construction", "combat"}


def test_list_plain_text(capsys):
    assert main(["captions", "list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 61 and "obtain wood" in lines[0]


def test_print_prompt_follows_the_paper(capsys):
    argv = ["captions", "paraphrase", "--print-prompt", "--caption", "kill cow", "--n", "7"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "generate 7 unique captions" in out and "- kill cow" in out
    assert "avoid generating title-like sentences." in out


def test_paraphrase_without_endpoint_is_a_usage_error(capsys):
    with pytest.raises(SystemExit):
        main(["captions", "paraphrase"])
    assert "--endpoint and --model are required" in capsys.readouterr().err


def test_unknown_caption_is_refused(capsys):
    assert main(["captions", "paraphrase", "--print-prompt", "--caption", "attack cow"]) == 2
    assert "attack cow" in capsys.readouterr().err


def test_prompt_lists_each_caption():
    prompt = build_paraphrase_prompt(["stay", "go explore"], 50)
    assert "- stay\n- go explore\n</captions>" in prompt


def test_reply_parsing_drops_repeats_unknown_keys_and_fences():
    reply = (
        '```yaml\n"stay":\n  - "wait"\n  - "wait"\n  - "stay"\n  - " hold still "\n'
        '"fly": ["x"]\n```'
    )
    assert parse_paraphrase_reply(reply, ["stay", "go explore"]) == {
        "stay": ["wait", "hold still"],
        "go explore": [],
    }


def test_reply_that_is_not_yaml_mapping_is_an_error():
    with pytest.raises(ValueError, match="mapping"):
        parse_paraphrase_reply("- a\n- b", ["stay"])
