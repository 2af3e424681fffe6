"""The review API's routes, one router per resource; each is a thin translation of HTTP to
one call of the service layer (`workflow`, `adjudication`, `views`, `auth`)."""
