//! Making users and their API tokens, shared by the CLI (`terraplan user`),
//! the first start of `terraplan serve` and `POST /api/v1/users`: the
//! name and password rules, the personal project every user gets, and the
//! adoption of resources made before accounts by the first admin.

use super::password;
use super::secret::{self, TOKEN_PREFIX};
use crate::clock::now_millis;
use crate::db::{Db, ProjectRow, TokenRow, UserRow};

/// Longest user name, in characters.
pub const NAME_MAX_CHARS: usize = 64;
/// The name of the admin made on first start.
pub const FIRST_ADMIN: &str = "admin";

/// Why an account operation failed.
#[derive(Debug, thiserror::Error)]
pub enum AccountError {
    /// A bad name or password; the message names the fault.
    #[error("{0}")]
    Invalid(String),
    /// The user name is taken.
    #[error("there is already a user named {0:?}")]
    Exists(String),
    /// No user of that name.
    #[error("there is no user named {0:?}")]
    UnknownUser(String),
    #[error("database: {0}")]
    Db(#[from] sqlx::Error),
}

/// Why `name` cannot be a user name; `None` when it can.
pub fn name_fault(name: &str) -> Option<String> {
    let chars = name.chars().count();
    if chars == 0 {
        return Some("a user name may not be empty".to_string());
    }
    if chars > NAME_MAX_CHARS {
        return Some(format!(
            "a user name has at most {NAME_MAX_CHARS} characters, this one {chars}"
        ));
    }
    name.chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-')))
        .map(|c| format!("a user name may hold only letters, digits, '.', '_' and '-', not {c:?}"))
}

/// A user just made, with its first API token (shown once).
pub struct NewUser {
    pub user: UserRow,
    pub personal_project_id: String,
    pub token: String,
    /// Resources made before accounts that this (first) admin adopted.
    pub adopted: u64,
}

/// Make user `name` (with `password`, if any), its personal project and a
/// first API token. The first admin made adopts every resource of no
/// project.
pub async fn create_user(
    db: &Db,
    name: &str,
    password: Option<&str>,
    admin: bool,
) -> Result<NewUser, AccountError> {
    if let Some(fault) = name_fault(name) {
        return Err(AccountError::Invalid(fault));
    }
    if let Some(fault) = password.and_then(password::fault) {
        return Err(AccountError::Invalid(fault));
    }
    if db.user_by_name(name).await?.is_some() {
        return Err(AccountError::Exists(name.to_string()));
    }
    let first_admin = admin && db.count_admins().await? == 0;
    let now = now_millis();
    let user = UserRow {
        id: uuid::Uuid::now_v7().to_string(),
        name: name.to_string(),
        password_hash: password.map(password::hash),
        admin: i64::from(admin),
        disabled: 0,
        created_at: now,
    };
    db.insert_user(&user).await.map_err(|e| match &e {
        // Made by someone else since the look-up above.
        sqlx::Error::Database(d) if d.is_unique_violation() => {
            AccountError::Exists(name.to_string())
        }
        _ => AccountError::Db(e),
    })?;
    let project = ProjectRow {
        id: uuid::Uuid::now_v7().to_string(),
        name: name.to_string(),
        personal_of: Some(user.id.clone()),
        created_at: now,
    };
    db.insert_project(&project, &user.id).await?;
    let adopted = if first_admin {
        db.adopt_unowned_resources(&project.id).await?
    } else {
        0
    };
    let (_, token) = issue_token(db, &user.id, "made with the user", None).await?;
    Ok(NewUser {
        user,
        personal_project_id: project.id,
        token,
        adopted,
    })
}

/// A new API token of `user_id`: its row and the token itself (shown once).
pub async fn issue_token(
    db: &Db,
    user_id: &str,
    name: &str,
    expires_at: Option<i64>,
) -> Result<(TokenRow, String), sqlx::Error> {
    let s = secret::new_secret(TOKEN_PREFIX);
    let row = TokenRow {
        id: s.id,
        user_id: user_id.to_string(),
        name: name.to_string(),
        secret_hash: s.hash,
        created_at: now_millis(),
        last_used_at: None,
        expires_at,
    };
    db.insert_token(&row).await?;
    Ok((row, s.full))
}

/// The enabled-or-not user named `name`.
pub async fn user_named(db: &Db, name: &str) -> Result<UserRow, AccountError> {
    if let Some(fault) = name_fault(name) {
        return Err(AccountError::Invalid(fault));
    }
    db.user_by_name(name)
        .await?
        .ok_or_else(|| AccountError::UnknownUser(name.to_string()))
}

/// What the first start of a service with no users made: the admin's
/// one-time password and an API token.
pub struct FirstStart {
    pub password: String,
    pub token: String,
    pub adopted: u64,
}

/// On a service with no users, make the admin `admin` with a generated
/// password; `None` when there are users already.
pub async fn first_start(db: &Db) -> Result<Option<FirstStart>, AccountError> {
    if db.count_users().await? > 0 {
        return Ok(None);
    }
    let password = password::generate();
    match create_user(db, FIRST_ADMIN, Some(&password), true).await {
        Ok(made) => Ok(Some(FirstStart {
            password,
            token: made.token,
            adopted: made.adopted,
        })),
        // Another server on the same database made it at the same time.
        Err(AccountError::Exists(_)) => Ok(None),
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn temp_db() -> (Db, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("terraplan-acc-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        (Db::connect(None, &dir).await.unwrap(), dir)
    }

    #[test]
    fn user_name_rules() {
        assert!(name_fault("alice").is_none());
        assert!(name_fault("a.b_c-9").is_none());
        assert!(name_fault(&"x".repeat(64)).is_none());
        assert!(name_fault("").unwrap().contains("empty"));
        assert!(name_fault(&"x".repeat(65)).unwrap().contains("64"));
        assert!(name_fault("a b").unwrap().contains("' '"));
        assert!(name_fault("<b>").unwrap().contains("'<'"));
        assert!(name_fault("é").is_some());
    }

    #[tokio::test]
    async fn users_get_a_personal_project_and_a_working_token() {
        let (db, dir) = temp_db().await;
        let made = create_user(&db, "alice", Some("long enough"), false)
            .await
            .unwrap();
        assert_eq!(made.user.name, "alice");
        let project = db.personal_project(&made.user.id).await.unwrap().unwrap();
        assert_eq!(project.id, made.personal_project_id);
        assert_eq!(
            db.member_role(&project.id, &made.user.id)
                .await
                .unwrap()
                .as_deref(),
            Some("owner")
        );
        let caller = crate::auth::caller::token_caller(&db, &made.token)
            .await
            .unwrap();
        assert_eq!(caller.name, "alice");
        assert!(!caller.admin);
        let stored = db.user_by_name("alice").await.unwrap().unwrap();
        assert!(password::verify(
            "long enough",
            stored.password_hash.as_deref().unwrap()
        ));
        assert!(matches!(
            create_user(&db, "alice", None, false).await,
            Err(AccountError::Exists(_))
        ));
        assert!(matches!(
            create_user(&db, "bob", Some("short"), false).await,
            Err(AccountError::Invalid(m)) if m.contains("at least 8")
        ));
        assert!(matches!(
            user_named(&db, "carol").await,
            Err(AccountError::UnknownUser(_))
        ));
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[tokio::test]
    async fn the_first_start_makes_admin_once() {
        let (db, dir) = temp_db().await;
        let first = first_start(&db).await.unwrap().expect("no users yet");
        assert_eq!(first.password.len(), 20);
        let admin = db.user_by_name(FIRST_ADMIN).await.unwrap().unwrap();
        assert_eq!(admin.admin, 1);
        assert!(password::verify(
            &first.password,
            admin.password_hash.as_deref().unwrap()
        ));
        let caller = crate::auth::caller::token_caller(&db, &first.token)
            .await
            .unwrap();
        assert!(caller.admin);
        assert!(first_start(&db).await.unwrap().is_none(), "only once");
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }
}
