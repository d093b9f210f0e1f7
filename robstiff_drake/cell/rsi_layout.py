"""A fast reader for the controller's RSI datagrams, learnt from one the XML
parser accepted.

A KUKA controller sends, every cycle, the same document (the SEND section of
its RSI_EthernetConfig.xml): the same elements in the same order with the
same attributes; only the values and the IPOC change.  From a datagram the
full parser (``rsi.decode_rob``'s ElementTree) accepted, ``RobLayout.learn``
compiles one regular expression: that document's bytes, literal, with each
attribute value replaced by a run of characters that need no XML
processing (printable ASCII without quotes, '<', '&'; a group only for the
values read: A1..A6 of the axes' elements) and each text by such
text (the IPOC's by 1 to 19 ASCII digits between spaces or newlines).  A
datagram the expression matches whole is then the same tree as the learnt
one with other values, read by the XML parser as exactly the characters the
groups hold (no references, no whitespace normalisation, no namespaces, no
duplicate attribute, tags matching): so reading them here gives what the
parser would give.  Learnt only from a simple document (ASCII, flat: a root
holding elements with attributes or text, no processing instruction, no
reference) and only if reading it back gives what the parser gave;
a datagram that does not match, or a value that is not a number, goes to
the full parser, which decides with its own errors.

Why this and not another parser: measured on one datagram, in-process on
the development machine, ElementTree reads it in about 10 us, expat
(xml.parsers.expat, ElementTree's own parser) called directly with
handlers in 9.6 us (the Python handler calls cost what the tree saved),
lxml 6.1 in 12.7 us with the element look-ups (and a compiled dependency),
a general regular grammar of flat XML in 18 us (attribute dictionaries in
Python); the learnt layout reads it in 2.8 us, and the parser stays the
judge of anything else.  Measured again side by side on the tests' KRC4
datagram and a fuller one of 658 bytes (benchmarks/bench_rsi_codec.py;
docs/results.md section 5, RSI's XML side by side): ElementTree 13-20 us,
its pull parser 15-20, expat with handlers 10-15 (a parser per datagram:
expat cannot be reset, and one fed every datagram as a fragment of an
endless document carries one datagram's errors and state to the next),
the layout 3-4 us; spaced as the loop calls them (caches partly cold)
55-60, 36-46 and 19-20 us.  lxml is not installed (not a dependency).
Only the values read are captured (the others match uncaptured): 3.6 ->
3.1 us (KRC), 5.1 -> 4.3 us (658 bytes).
"""

import re
from operator import itemgetter

_S = rb"[ \t\r\n]"  # (a CR only in the layout's literal parts and around the IPOC: never in a value read)
_NAME = rb"[A-Za-z_][A-Za-z0-9_]*"  # no ':' (no namespaces), no '.' or '-'
_DQ = rb'[^"<&\x00-\x1f\x7f-\xff]*'
_SQ = rb"[^'<&\x00-\x1f\x7f-\xff]*"
_TEXT = rb"[^<>&\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\xff]*"  # (tab, CR, newline: only the IPOC's text is read, stripped)
_ATTR = _S + rb"+(" + _NAME + rb")" + _S + rb"*=" + _S + rb"*(?:\"(" + _DQ + rb")\"|'(" + _SQ + rb")')"
_ATTRS = rb"(?:" + _S + rb"+" + _NAME + _S + rb"*=" + _S + rb"*(?:\"" + _DQ + rb"\"|'" + _SQ + rb"'))*"
_ATTR_RE = re.compile(_ATTR)
_ROOT_RE = re.compile(_S + rb"*<(" + _NAME + rb")(" + _ATTRS + rb")" + _S + rb"*>(.*)</\1" + _S + rb"*>" + _S
                      + rb"*\Z", re.DOTALL)
_CHILD_RE = re.compile(_S + rb"*<(" + _NAME + rb")(" + _ATTRS + rb")" + _S + rb"*(?:/>|>(" + _TEXT + rb")</\1"
                       + _S + rb"*>)")
_IPOC_TEXT = _S + rb"*([0-9]{1,19})" + _S + rb"*"


class RobLayout:
    """The compiled layout of one controller's datagrams (``read`` gives
    what ``rsi.decode_rob`` gives, or None)."""

    def __init__(self, regex, ipoc_group, axes_groups):
        self.regex = regex
        self.ipoc_group = ipoc_group
        self.axes_groups = axes_groups  # {tag: [group of A1..A6]}
        # (the groups' values of A1..A6 per tag in one C call: itemgetter of their indices in match.groups())
        self._get = {t: itemgetter(*[i - 1 for i in g]) if len(g) > 1 else (lambda v, i=g[0] - 1: (v[i],))
                     for t, g in axes_groups.items()}

    @classmethod
    def learn(cls, data, root_tag, axes_tags, axes_names, decoded):
        """The layout of ``data`` (which the full parser read as
        ``decoded``), or None when it is not a simple document or reading
        it back differs."""
        if not data.isascii() or b"<?" in data or b"&" in data or b"<!" in data:
            return None
        root = _ROOT_RE.match(data)
        if root is None or root.group(1).decode() != root_tag:
            return None
        body_at = root.start(3)
        pieces = [re.escape(data[:body_at])]
        groups, seen, at = 0, set(), body_at
        ipoc_group, axes = None, {}
        while at < root.end(3):
            el = _CHILD_RE.match(data, at, root.end(3))
            if el is None:
                if data[at:root.end(3)].strip(b" \t\r\n"):
                    return None  # not a flat document
                break
            name = el.group(1).decode()
            if name.lower().startswith("xml"):
                return None
            first = name not in seen
            seen.add(name)
            attrs, names, pos = set(), {}, el.start()
            for a in _ATTR_RE.finditer(data, el.start(2), el.end(2)):
                vg = 2 if a.group(2) is not None else 3
                attr = a.group(1).decode()
                if attr in attrs or attr.lower().startswith("xml"):
                    return None
                attrs.add(attr)
                # (only the values read are captured; the others match the same characters, uncaptured)
                capture = first and name in axes_tags and attr in axes_names
                pieces += [re.escape(data[pos:a.start(vg)]),
                           (b"(" if capture else b"(?:") + (_DQ if vg == 2 else _SQ) + b")"]
                pos = a.end(vg)
                if capture:
                    groups += 1
                    names[attr] = groups
            if first and name in axes_tags:
                if any(n not in names for n in axes_names):
                    return None
                axes[name] = [names[n] for n in axes_names]
            if el.group(3) is not None:
                pieces.append(re.escape(data[pos:el.start(3)]))
                if first and name == "IPOC":
                    pieces.append(_IPOC_TEXT)
                    groups += 1
                    ipoc_group = groups
                else:
                    pieces.append(b"(?:" + _TEXT + b")")
                pos = el.end(3)
            pieces.append(re.escape(data[pos:el.end()]))
            at = el.end()
        layout = cls._finish(pieces, data[at:], ipoc_group, axes, axes_tags, axes_names)
        return layout if layout is not None and layout.read(data, axes_tags) == tuple(decoded) else None

    @classmethod
    def _finish(cls, pieces, tail, ipoc_group, axes, axes_tags, axes_names):
        if ipoc_group is None or axes_tags[0] not in axes:
            return None
        return cls(re.compile(b"".join(pieces) + re.escape(tail) + rb"\Z"), ipoc_group, axes)

    def read(self, data, axes_tags=("AIPos", "ASPos")):
        """(IPOC, A1..A6 deg or None per tag ...) or None (no match, or a
        value float() refuses: the full parser decides)."""
        m = self.regex.match(data)
        if m is None:
            return None
        g = m.groups()
        get = self._get
        try:
            axes = [list(map(float, get[t](g))) if t in get else None for t in axes_tags]
        except ValueError:
            return None
        return (int(g[self.ipoc_group - 1]), *axes)
