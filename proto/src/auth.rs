//! Tokens and roles. A coordinator may require one token of its workers
//! and another of its clients (`authorization: Bearer TOKEN`); the check
//! records which role(s) the caller's token grants, and each method asks
//! for its role, so that a client's token cannot take a worker's tasks and
//! a worker's token cannot submit, watch or cancel jobs. With no token
//! configured, every caller has both roles (a warning is logged at start).

use tonic::metadata::MetadataValue;
use tonic::{Request, Status};

/// A shared secret, read from a file (surrounding whitespace ignored).
#[derive(Clone)]
pub struct Token(String);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(..)")
    }
}

impl Token {
    pub fn new(s: &str) -> Result<Token, String> {
        let t = s.trim();
        if t.is_empty() {
            return Err("the token is empty".into());
        }
        if t.len() > 4096 || !t.bytes().all(|b| b.is_ascii_graphic()) {
            return Err("a token is up to 4096 printable ASCII characters without spaces".into());
        }
        Ok(Token(t.to_string()))
    }

    pub fn from_file(path: &std::path::Path) -> Result<Token, String> {
        let s = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read the token file {}: {e}", path.display()))?;
        Token::new(&s).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Compares in time independent of where the first difference lies.
    fn matches(&self, given: &[u8]) -> bool {
        crate::ids::same(given, self.0.as_bytes())
    }
}

const HEADER: &str = "authorization";

/// What a caller's token lets it do; put in the request's extensions by
/// [`Check`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Granted {
    pub worker: bool,
    pub client: bool,
}

/// The roles a method needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Worker,
    Client,
}

/// Server side: refuses requests without a known token (if any is
/// configured) and records the roles the token grants.
#[derive(Clone, Debug, Default)]
pub struct Check {
    pub worker: Option<Token>,
    pub client: Option<Token>,
}

impl Check {
    /// One token for both roles (a cluster that does not separate them).
    pub fn shared(t: Option<Token>) -> Check {
        Check {
            worker: t.clone(),
            client: t,
        }
    }

    fn open(&self) -> bool {
        self.worker.is_none() && self.client.is_none()
    }
}

impl tonic::service::Interceptor for Check {
    fn call(&mut self, mut req: Request<()>) -> Result<Request<()>, Status> {
        if self.open() {
            req.extensions_mut().insert(Granted {
                worker: true,
                client: true,
            });
            return Ok(req);
        }
        let given = req
            .metadata()
            .get(HEADER)
            .and_then(|v| v.as_bytes().strip_prefix(b"Bearer "));
        let Some(g) = given else {
            tracing::warn!(peer = ?req.remote_addr(), "refused a call without a token");
            return Err(Status::unauthenticated(
                "this coordinator requires a token (--token-file)",
            ));
        };
        let granted = Granted {
            worker: self.worker.as_ref().is_some_and(|t| t.matches(g)),
            client: self.client.as_ref().is_some_and(|t| t.matches(g)),
        };
        if !granted.worker && !granted.client {
            tracing::warn!(peer = ?req.remote_addr(), "refused a call with a wrong token");
            return Err(Status::unauthenticated("wrong token"));
        }
        req.extensions_mut().insert(granted);
        Ok(req)
    }
}

/// Whether the request's token grants `role`; logs and refuses if not.
pub fn require<T>(req: &Request<T>, role: Role, method: &str) -> Result<(), Status> {
    let g = req
        .extensions()
        .get::<Granted>()
        .copied()
        .unwrap_or_default();
    let ok = match role {
        Role::Worker => g.worker,
        Role::Client => g.client,
    };
    if ok {
        return Ok(());
    }
    tracing::warn!(peer = ?req.remote_addr(), method, ?role, "refused a call: the token does not grant this role");
    Err(Status::permission_denied(match role {
        Role::Worker => "this token is not a worker's: only workers may call this",
        Role::Client => "this token is not a client's: only clients may call this",
    }))
}

/// Client side: adds the token to every request (if one is configured).
#[derive(Clone, Debug)]
pub struct Attach(pub Option<Token>);

impl tonic::service::Interceptor for Attach {
    fn call(&mut self, mut req: Request<()>) -> Result<Request<()>, Status> {
        if let Some(t) = &self.0 {
            let v: MetadataValue<_> = format!("Bearer {}", t.0)
                .parse()
                .map_err(|_| Status::internal("token is not a valid header value"))?;
            req.metadata_mut().insert(HEADER, v);
        }
        Ok(req)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::service::Interceptor;

    #[test]
    fn the_check_wants_a_known_token_and_grants_its_role() {
        let w = Token::new(" w0rker\n").unwrap();
        let c = Token::new("cl1ent").unwrap();
        let mut check = Check {
            worker: Some(w.clone()),
            client: Some(c.clone()),
        };
        let req = check
            .call(Attach(Some(w)).call(Request::new(())).unwrap())
            .unwrap();
        assert!(require(&req, Role::Worker, "t").is_ok());
        assert_eq!(
            require(&req, Role::Client, "t").unwrap_err().code(),
            tonic::Code::PermissionDenied
        );
        let req = check
            .call(Attach(Some(c)).call(Request::new(())).unwrap())
            .unwrap();
        assert!(require(&req, Role::Client, "t").is_ok());
        assert!(require(&req, Role::Worker, "t").is_err());
        assert!(check.call(Request::new(())).is_err());
        let wrong = Attach(Some(Token::new("cl1enT").unwrap()))
            .call(Request::new(()))
            .unwrap();
        assert_eq!(
            check.call(wrong).unwrap_err().code(),
            tonic::Code::Unauthenticated
        );
        // No token configured: anyone may call, in either role.
        let req = Check::default().call(Request::new(())).unwrap();
        assert!(require(&req, Role::Worker, "t").is_ok());
        assert!(require(&req, Role::Client, "t").is_ok());
        assert!(Token::new("  ").is_err());
        assert!(Token::new("has space").is_err());
    }
}
