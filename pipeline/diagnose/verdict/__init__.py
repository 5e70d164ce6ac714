"""The verdict of a diagnosis: what may be reported as found, and with what confidence.

- `checks`: pure tests — the held-out arbiter's rules, back to the noise floor, misspecification,
  influence of single records, status;
- `arbiter`: applies them to the findings (held-out error decides, records that carry a finding,
  twins);
- `outliers`: the influence screen around a diagnosis (records set aside, the diagnosis re-run);
- `lack_of_fit`: smooth-basis and scan tests that locate structure no accepted term explains;
  `physical_lack_of_fit`: the same under an adapter's physical cluster-error model;
- `grading`: where the rest is, each finding's confidence, the floor and the status.
"""
