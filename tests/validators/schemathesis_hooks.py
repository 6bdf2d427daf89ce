"""Schemathesis checks of terraplan's own (loaded with SCHEMATHESIS_HOOKS).

`refused_without_credentials`: for the pass without credentials, every
operation whose OpenAPI entry requires a security scheme must answer 401
(problem+json), whatever schemathesis generated for it.
"""

import schemathesis


@schemathesis.check
def refused_without_credentials(ctx, response, case):
    if case.method.upper() != case.operation.method.upper():
        # An undocumented method (schemathesis' unsupported-method phase):
        # no operation, so nothing to require credentials for.
        return None
    requires = list(case.operation.security.iter_parameters())
    if not requires:
        return None
    if response.status_code != 401:
        raise AssertionError(
            f"{case.method} {case.formatted_path} answered {response.status_code} without "
            "credentials; every operation that requires them must answer 401"
        )
    content_type = response.headers.get("content-type", [""])
    if isinstance(content_type, list):
        content_type = content_type[0] if content_type else ""
    if not content_type.startswith("application/problem+json"):
        raise AssertionError(f"the 401 of {case.method} {case.formatted_path} is {content_type!r}, not problem+json")
    return None
