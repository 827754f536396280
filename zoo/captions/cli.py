"""`zoo captions list|paraphrase` and `zoo data caption` (the latter hung on the data group).

`paraphrase` asks an OpenAI-compatible chat endpoint for new paraphrases with the paper's
prompt (Appendix, "Caption Rephrasing Prompt") and prints YAML to review before merging into
paraphrases.yaml; the shipped bank is hand-written, so nothing here needs the network.
"""

from __future__ import annotations

import argparse
import json
import sys
import urllib.request

import yaml

from zoo.argtypes import add_out_flag
from zoo.captions.balance import BALANCE_MODES, BALANCE_UNITS, DEFAULT_BALANCE_UNIT
from zoo.captions.vocabulary import load_vocabulary

PROMPT = """<goal>
rewrite each video caption. generate {n} unique captions for each caption.
</goal>
<guidelines>
- focus on the behavior, do not introduce a new tools like sword if there is no sword \
in the original captions.
- avoid generating title-like sentences.
</guidelines>
<format>
"original 1":
  - "rephrased 1-1"
  - "rephrased 1-2"
"original 2":
  - "rephrased 2-1"
  - "rephrased 2-2"
</format>
<captions>
{captions}
</captions>"""


def build_paraphrase_prompt(captions: list[str], n: int) -> str:
    """The paper's rephrasing prompt for these captions."""
    return PROMPT.format(n=n, captions="\n".join(f"- {c}" for c in captions))


def parse_paraphrase_reply(text: str, captions: list[str]) -> dict[str, list[str]]:
    """The model's YAML reply -> caption -> unique paraphrases (code fences and unknown keys
    dropped, the caption itself and repeats removed)."""
    body = text.strip()
    if body.startswith("```"):
        body = body.split("\n", 1)[1].rsplit("```", 1)[0]
    try:
        data = yaml.safe_load(body)
    except yaml.YAMLError as err:
        raise ValueError(f"reply is not the YAML the prompt asks for: {err}") from None
    if not isinstance(data, dict):
        raise ValueError("reply is not a mapping of caption -> list of paraphrases")
    out = {}
    for caption in captions:
        variants = data.get(caption) or []
        unique = dict.fromkeys(
            v.strip() for v in variants if isinstance(v, str) and v.strip() and v.strip() != caption
        )
        out[caption] = list(unique)
    return out


def request_paraphrases(endpoint: str, model: str, prompt: str, timeout: float = 300) -> str:
    """POST the prompt to ``{endpoint}/chat/completions``; return the reply text."""
    payload = {"model": model, "messages": [{"role": "user", "content": prompt}]}
    request = urllib.request.Request(
        endpoint.rstrip("/") + "/chat/completions",
        data=json.dumps(payload).encode(),
        headers={"Content-Type": "application/json"},
    )
    with urllib.request.urlopen(request, timeout=timeout) as response:
        return json.loads(response.read())["choices"][0]["message"]["content"]


def _list(args: argparse.Namespace) -> int:
    vocab = load_vocabulary()
    rows = [
        {
            "id": c.id, "caption": c.text, "rule": c.rule, "category": c.category,
            "paraphrases": list(vocab.paraphrases.get(c.text, ())),
        }
        for c in vocab.captions
    ]
    if args.json:
        json.dump(rows, sys.stdout, indent=1)
        print()
    else:
        for r in rows:
            n = len(r["paraphrases"])
            head = f"{r['id']:2d}  {r['category']:<12} {r['rule']:<12}"
            print(f"{head} {r['caption']}  ({n} paraphrases)")
    return 0


def _paraphrase(args: argparse.Namespace) -> int:
    vocab = load_vocabulary()
    captions = args.caption or vocab.texts()
    unknown = [c for c in captions if c not in vocab]
    if unknown:
        print(f"not captions: {unknown}", file=sys.stderr)
        return 2
    prompt = build_paraphrase_prompt(captions, args.n)
    if args.print_prompt:
        print(prompt)
        return 0
    reply = request_paraphrases(args.endpoint, args.model, prompt)
    parsed = parse_paraphrase_reply(reply, captions)
    print(yaml.safe_dump(parsed, sort_keys=False, allow_unicode=True))
    return 0


def format_shares(shares: dict[str, float]) -> str:
    """``name 12.3%, ...`` for the names that kept clips (a summary line, not the manifest)."""
    return ", ".join(f"{name} {share:.1%}" for name, share in shares.items() if share)


def _caption(args: argparse.Namespace) -> int:
    from zoo.captions.dataset import caption_dataset

    try:
        manifest = caption_dataset(
            args.src, args.out, seed=args.seed, balance=args.balance,
            balance_unit=args.balance_unit, per_unit=args.per_unit,
            heldout_episodes=args.heldout_episodes, val_episodes=args.val_episodes,
            per_shard=args.per_shard, progress=True,
        )
    except (FileNotFoundError, ValueError) as err:  # bad --src or options: one line, no traceback
        print(f"zoo data caption: {err}", file=sys.stderr)
        return 2
    sizes = {s: m["samples"] for s, m in manifest["splits"].items()}
    how = f"balanced per {args.balance_unit}" if args.balance == "uniform" else "unbalanced"
    print(f"wrote {sizes} clip-caption pairs to {args.out} ({how})")
    for split, meta in manifest["splits"].items():
        print(f"{split} shares by category: {format_shares(meta['shares']['categories'])}")
        print(f"{split} shares by rule: {format_shares(meta['shares']['rules'])}")
    return 0


def _query(args: argparse.Namespace) -> int:
    from zoo.captions.query import run_query

    return run_query(args)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `zoo captions list|paraphrase|query`."""
    captions = subparsers.add_parser("captions", help="the 61 CrafterCaption captions, paraphrases")
    sub = captions.add_subparsers(dest="captions_command", metavar="ACTION", required=True)
    listing = sub.add_parser("list", help="print every caption with its rule and category")
    listing.add_argument("--json", action="store_true", help="JSON list with paraphrases")
    listing.set_defaults(handler=_list)
    para = sub.add_parser("paraphrase", help="ask an OpenAI-compatible endpoint for paraphrases")
    para.add_argument("--endpoint", help="base URL, e.g. http://localhost:8000/v1")
    para.add_argument("--model", help="model name the endpoint serves")
    para.add_argument("--n", type=int, default=50, help="paraphrases asked per caption (paper: 50)")
    para.add_argument("--caption", action="append", help="caption to rephrase (repeatable)")
    para.add_argument("--print-prompt", action="store_true", help="print the prompt, send nothing")

    def check(args: argparse.Namespace) -> int:
        if not args.print_prompt and not (args.endpoint and args.model):
            para.error("--endpoint and --model are required unless --print-prompt is given")
        return _paraphrase(args)

    para.set_defaults(handler=check)
    query = sub.add_parser(
        "query",
        help="zero-shot: the captions a trained C-CLIP finds best for a clip",
        description="Print the k best of the 61 captions for one clip, `score<TAB>caption` "
        "per line. A clip is a CrafterCaption sample's frames file (.npy.zst, extract it from "
        "a shard with `tar xf`) or any uint8 (6, 144, 144, 3) .npy.",
    )
    query.add_argument("--checkpoint", required=True, help="C-CLIP .ckpt from `zoo fit`")
    query.add_argument("--clip", required=True, help="uint8 (6, 144, 144, 3) .npy or .npy.zst")
    query.add_argument("--k", type=int, default=5, help="how many captions to print")
    query.add_argument("--device", default="cpu", help="torch device, e.g. cuda")
    query.set_defaults(handler=_query)


def register_data_commands(data_subparsers: argparse._SubParsersAction) -> None:
    """Add `zoo data caption` to the data group (called by zoo/data/cli.py)."""
    cap = data_subparsers.add_parser(
        "caption", help="CrafterPlay shards -> category-balanced CrafterCaption shards"
    )
    cap.add_argument("--src", required=True, help="CrafterPlay folder (with manifest.json)")
    add_out_flag(cap, "output folder for the caption shards")
    cap.add_argument("--seed", type=int, default=0, help="seeds the held-out split and balancing")
    cap.add_argument("--balance", choices=BALANCE_MODES, default="uniform",
                     help="uniform: same number of clips per --balance-unit (paper); "
                     "none: keep all")
    cap.add_argument("--balance-unit", choices=BALANCE_UNITS, default=None,
                     help=f"what uniform balancing evens out (default {DEFAULT_BALANCE_UNIT}, the "
                     "paper's 'rule categories'); inside a unit clips are spread evenly over its "
                     "rules, then captions")
    quota = cap.add_mutually_exclusive_group()
    quota.add_argument("--per-unit", type=int, default=None, metavar="K",
                       help="clips per unit when balancing (default: the rarest unit's count)")
    quota.add_argument("--per-rule", type=int, default=None, metavar="K",
                       help="K clips per rule: short for --balance-unit rule --per-unit K")
    cap.add_argument("--heldout-episodes", type=int, default=1000,
                     help="episodes held out for the test split (paper: 1000); with fewer "
                     "episodes in the input, 5%% of them (at least one)")
    cap.add_argument("--val-episodes", type=int, default=0,
                     help="other episodes for a validation split that picks checkpoints, so the "
                     "test split is only scored (default 0: no val split)")
    cap.add_argument("--per-shard", type=int, default=1000, help="clips per shard")

    def resolve_unit(args: argparse.Namespace) -> int:
        """--per-rule keeps its old meaning (a quota per rule), so it implies the rule unit."""
        if args.per_rule is not None:
            if args.balance_unit == "category":
                cap.error("--per-rule balances rules; use --per-unit with --balance-unit category")
            args.balance_unit, args.per_unit = "rule", args.per_rule
        args.balance_unit = args.balance_unit or DEFAULT_BALANCE_UNIT
        return _caption(args)

    cap.set_defaults(handler=resolve_unit)
