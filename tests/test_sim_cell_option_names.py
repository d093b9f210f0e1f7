"""sim-cell's option for the compensator's address is named for what it is
whatever the protocol (--compensator), not for ABB's EGM alone: a KUKA user
running `sim-cell --controller-protocol rsi` was asked for --egm-to, "where
the compensator listens for EGM".  --egm-to stays as the older name."""

from robstiff_drake.commands.parser import build_parser


def test_the_compensator_address_has_a_protocol_neutral_name():
    parser = build_parser()
    for option in ("--compensator", "--egm-to"):
        args = parser.parse_args(["sim-cell", "short_block", option, "127.0.0.1:16511", "--netft-port", "49252",
                                  "--controller-protocol", "rsi"])
        assert args.egm_to == "127.0.0.1:16511"
    sub = next(a for a in parser._subparsers._group_actions[0].choices.items() if a[0] == "sim-cell")[1]
    text = sub.format_help()
    assert "--compensator HOST:PORT" in text and "RSI" in text and "Stream Motion" in text
