"""Numbers of a json-xz document (``json_xz``'s module docstring): columns written as exact decimal differences
(``differences``, added up again by ``sums``), and the opt-in lossy rounding of fields to a step
(``check_precision``, ``max_errors``).
"""
import decimal
import fnmatch
import math
import operator
import re

from cc_log.base import msg_codec
from cc_log.storage.formats.json_rows import flatten

#: A float column is delta-coded when its differences have at most this share of its values' significant
#: digits, and at most REPEATS_SHARE of its values repeat an earlier value that is not the one just before.
#: Measured on the Husky odometry (docs/FORMAT.md): positions (0.80 of the digits) compress 25% smaller,
#: angular velocity (0.87) 3.5%, linear velocity (0.84) 1% larger; orientations (0.53, but a third of their
#: values recur) 15% larger.
DELTA_GAIN = 0.87
REPEATS_SHARE = 0.1
#: Float columns longer than twice SAMPLE are first tried on their first SAMPLE values: beyond SAMPLE_GAIN of
#: the digits there, the column stays plain (the Husky positions: 0.88-0.91 on their first 50 values).
SAMPLE = 50
SAMPLE_GAIN = 0.97
#: Decimal arithmetic for differences: exact for any double's shortest text (at most 17 digits, exponents
#: -324..308) and any difference of two; a document needing more is refused (decimal.Inexact).
_EXACT = decimal.Context(prec=400, Emin=-999, Emax=999,
                         traps=[decimal.Inexact, decimal.Overflow, decimal.InvalidOperation])


# -- differences ----------------------------------------------------------------------------------------

def _is_int(value):
    return isinstance(value, int) and not isinstance(value, bool)


def _is_plain_float(value):
    """A finite float that is not -0.0 (whose sign a sum of differences does not keep)."""
    return isinstance(value, float) and math.isfinite(value) and not (value == 0.0 and math.copysign(1.0, value) < 0)


def decimal_text(value):
    """The JSON text of a Decimal: ``0``, else the shorter of plain and scientific notation, no trailing
    zeros."""
    if not value:
        return '0'
    value = value.normalize(_EXACT)
    scientific = str(value)
    if 'E' not in scientific:
        return scientific  # plain already, as format(value, 'f') writes it
    plain = format(value, 'f')
    return plain if len(plain) <= len(scientific) else scientific


def differences(values, choose=True):
    """``values`` as their first value and differences (ints, or Decimals for floats), or None when they
    are not all integers or all finite floats (no -0.0), or (``choose``) when the plain column is likely
    smaller (integers: not shorter as text; floats: see DELTA_GAIN, REPEATS_SHARE and SAMPLE)."""
    if len(values) < 3:
        return None
    if set(map(type, values)) == {int} or all(_is_int(value) for value in values):
        deltas = values[:1] + [b - a for a, b in zip(values, values[1:])]
        return deltas if not choose or len(str(deltas)) < len(str(values)) else None
    if not _plain_floats(values):
        return None
    if choose and len(values) > 2 * SAMPLE and _digit_share(values[:SAMPLE])[0] > SAMPLE_GAIN:
        return None  # decided on a sample: noisy columns (IMU axes) are not worth the decimal arithmetic
    texts = list(map(repr, values))
    if choose:  # the repeats first: they are cheaper to count than the digits
        adjacent = sum(1 for a, b in zip(texts, texts[1:]) if a == b)
        if len(texts) - len(set(texts)) - adjacent > REPEATS_SHARE * len(texts):
            return None
    share, deltas = _digit_share(values, texts)
    return None if choose and share > DELTA_GAIN else deltas


def _plain_floats(values):
    """``all(_is_plain_float(value) for value in values)``, in bulk for a list of floats."""
    if set(map(type, values)) != {float}:
        return all(_is_plain_float(value) for value in values)
    return all(map(math.isfinite, values)) and (0.0 not in values or all(map(_is_plain_float, values)))


def _digit_share(values, texts=None):
    """(significant digits of the differences / of the values, the differences); (inf, None) when they
    cannot be computed exactly. ``texts``: ``repr`` of the values, if already made. The differences are a
    ``Deltas`` list: their texts (``decimal_text``) are kept for ``dumps``."""
    texts = list(map(repr, values)) if texts is None else texts
    exact = list(map(decimal.Decimal, texts))
    try:
        deltas = Deltas(exact[:1] + list(map(_EXACT.subtract, exact[1:], exact)))
    except decimal.DecimalException:
        return math.inf, None
    deltas.texts = decimal_texts(deltas)
    return _digit_sum(deltas.texts) / max(1, _digit_sum(texts)), deltas


class Deltas(list):
    """Differences (Decimals) with their ``texts``."""

    texts = None


_NORMALIZED = operator.methodcaller('normalize', _EXACT)


def decimal_texts(values):
    """``decimal_text`` of each of the Decimals ``values``, in bulk: ``str`` of the normalized value is that
    text unless it is scientific (then the shorter of the two notations) or ``-0``."""
    texts = list(map(str, map(_NORMALIZED, values)))
    if '-0' in texts or 'E' in ''.join(texts):
        texts = [decimal_text(value) if 'E' in text or text == '-0' else text for value, text in zip(values, texts)]
    return texts


_EXPONENT = re.compile('[eE][-+]?[0-9]+')


def _digit_sum(texts):
    """``sum(map(_digits, texts))`` counted over the joined texts, exponents left out: every digit, less the
    zeros that lead a number (``0.00``...) and the texts that are ``0``."""
    joined = ',' + ',,'.join(texts) + ','  # every text between its own two commas
    if 'e' in joined or 'E' in joined:
        joined = _EXPONENT.sub('', joined)  # the mantissa's digits count
    joined = joined.replace(',-', ',')
    count = len(joined) - joined.count(',') - joined.count('.') - joined.count(',0,')
    lead = ',0.'
    leading = joined.count(lead)
    while leading:
        count -= leading
        lead += '0'
        leading = joined.count(lead)
    return count


def _digits(text):
    """Significant digits of a number's text (what LZMA pays for: leading zeros and the exponent are cheap)."""
    return len(text.lower().split('e')[0].lstrip('-').replace('.', '').lstrip('0'))


def sums(values, key):
    """The values of a delta column (first value, then differences) added up; floats exact in decimal."""
    if not values or not all(_is_int(value) or isinstance(value, decimal.Decimal) for value in values):
        raise ValueError('delta column %s: holds something other than numbers' % key)
    total = values[0]
    out = [total]
    try:
        for delta in values[1:]:
            exact = isinstance(total, decimal.Decimal) or isinstance(delta, decimal.Decimal)
            total = _EXACT.add(total, delta) if exact else total + delta
            out.append(total)
    except decimal.DecimalException:
        raise ValueError('delta column %s: differences do not add up exactly' % key)
    return out


# -- precision (lossy) ----------------------------------------------------------------------------------

_ROUNDING = decimal.Context(prec=60, rounding=decimal.ROUND_HALF_EVEN)


def check_precision(precision, name='precision'):
    """``{field pattern: step}`` with every step a finite number > 0, else ValueError('<name>: ...').
    ``precision`` is such a mapping, None (no rounding) or text ``'pattern=step, pattern=step'`` (a node
    parameter, a command-line option)."""
    if precision is None:
        return {}
    if isinstance(precision, str):
        items = [item.strip() for item in precision.split(',') if item.strip()]
        if not all(item.count('=') == 1 for item in items):
            raise ValueError('%s: %r is not "pattern=step, pattern=step, ..."' % (name, precision))
        precision = dict((pattern.strip(), step.strip()) for pattern, step in (item.split('=') for item in items))
    if not isinstance(precision, dict):
        raise ValueError('%s: a mapping of field patterns to steps (e.g. {"pose.pose.position.*": 1e-4}), '
                         'not %r' % (name, precision))
    checked = {}
    for pattern, step in precision.items():
        if not isinstance(pattern, str) or not pattern:
            raise ValueError('%s: %r is not a field pattern' % (name, pattern))
        if isinstance(step, str):
            try:
                step = float(step)
            except ValueError:
                pass
        if isinstance(step, bool) or not isinstance(step, (int, float)) or not 0 < step < float('inf'):
            raise ValueError('%s: %s: step %r is not a number > 0' % (name, pattern, step))
        checked[pattern] = float(step)
    return checked


def rounder(precision):
    """A function ``(key, value) -> value`` rounding the floats of fields matching ``precision``."""
    steps = [(pattern, decimal.Decimal(repr(step))) for pattern, step in check_precision(precision).items()]
    chosen = {}

    def round_value(value, step):
        if isinstance(value, list):
            return [round_value(item, step) for item in value]
        if not isinstance(value, float) or not math.isfinite(value):
            return value
        count = _ROUNDING.divide(decimal.Decimal(repr(value)), step).to_integral_value(decimal.ROUND_HALF_EVEN)
        return float(_ROUNDING.multiply(count, step)) + 0.0  # + 0.0: no -0.0

    def rounded(key, value):
        if key not in chosen:
            chosen[key] = next((step for pattern, step in steps if fnmatch.fnmatchcase(key, pattern)), None)
        step = chosen[key]
        return value if step is None else round_value(value, step)
    return rounded


def max_errors(records, back):
    """``{topic: {field: largest absolute difference}}`` of every float field (array elements included)
    between ``records`` and ``back`` (the same messages read back, e.g. after rounding); non-finite values
    must stay the same (else the error is ``inf``)."""
    errors = {}
    for a, b in zip(records, back):
        topic = errors.setdefault(a.topic, {})
        flat_b = flatten(msg_codec.to_dict(b.msg), '', {})
        for key, value in flatten(msg_codec.to_dict(a.msg), '', {}).items():
            pairs = zip(value, flat_b[key]) if isinstance(value, list) else [(value, flat_b[key])]
            for old, new in pairs:
                if isinstance(old, float) or isinstance(new, float):
                    error = abs(new - old) if math.isfinite(old) else (0.0 if repr(old) == repr(new) else math.inf)
                    topic[key] = max(topic.get(key, 0.0), error)
    return errors
