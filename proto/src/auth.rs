//! The shared token: when configured, every request to the coordinator must
//! carry it (`authorization: Bearer TOKEN`), workers' and clients' alike.

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
        let want = self.0.as_bytes();
        if given.len() != want.len() {
            return false;
        }
        given
            .iter()
            .zip(want)
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
    }
}

const HEADER: &str = "authorization";

/// Server side: refuses requests without the token (if one is configured).
#[derive(Clone, Debug)]
pub struct Check(pub Option<Token>);

impl tonic::service::Interceptor for Check {
    fn call(&mut self, req: Request<()>) -> Result<Request<()>, Status> {
        let Some(token) = &self.0 else {
            return Ok(req);
        };
        let given = req
            .metadata()
            .get(HEADER)
            .and_then(|v| v.as_bytes().strip_prefix(b"Bearer "));
        match given {
            Some(g) if token.matches(g) => Ok(req),
            Some(_) => Err(Status::unauthenticated("wrong token")),
            None => Err(Status::unauthenticated(
                "this coordinator requires a token (--token-file)",
            )),
        }
    }
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
    fn the_check_wants_exactly_the_token() {
        let t = Token::new(" s3cret\n").unwrap();
        let mut check = Check(Some(t.clone()));
        let mut attach = Attach(Some(t));
        let ok = attach.call(Request::new(())).unwrap();
        assert!(check.call(ok).is_ok());
        assert!(check.call(Request::new(())).is_err());
        let wrong = Attach(Some(Token::new("s3creT").unwrap()))
            .call(Request::new(()))
            .unwrap();
        assert_eq!(
            check.call(wrong).unwrap_err().code(),
            tonic::Code::Unauthenticated
        );
        // No token configured: anyone may call.
        assert!(Check(None).call(Request::new(())).is_ok());
        assert!(Token::new("  ").is_err());
        assert!(Token::new("has space").is_err());
    }
}
