//! Users, their API tokens and their sign-in sessions. Secrets arrive
//! here already hashed (see `crate::auth::secret`).

use super::Db;

/// A user account.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct UserRow {
    pub id: String,
    pub name: String,
    /// argon2id PHC string; `None` for users who sign in with tokens only.
    pub password_hash: Option<String>,
    pub admin: i64,
    pub disabled: i64,
    pub created_at: i64,
}

/// An API token (its secret only as a hash).
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct TokenRow {
    pub id: String,
    pub user_id: String,
    pub name: String,
    pub secret_hash: String,
    pub created_at: i64,
    pub last_used_at: Option<i64>,
    pub expires_at: Option<i64>,
}

/// A sign-in session of the web page.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct SessionRow {
    pub id: String,
    pub user_id: String,
    pub secret_hash: String,
    pub csrf_token: String,
    pub created_at: i64,
    pub last_used_at: i64,
    pub expires_at: i64,
}

// The columns of each row type, for `concat!` (SQL must be static).
macro_rules! user_columns {
    () => {
        "id, name, password_hash, admin, disabled, created_at"
    };
}
macro_rules! token_columns {
    () => {
        "id, user_id, name, secret_hash, created_at, last_used_at, expires_at"
    };
}
macro_rules! session_columns {
    () => {
        "id, user_id, secret_hash, csrf_token, created_at, last_used_at, expires_at"
    };
}

impl Db {
    pub async fn insert_user(&self, row: &UserRow) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO users (id, name, password_hash, admin, disabled, created_at) VALUES ($1, $2, $3, $4, $5, $6)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.name)
            .bind(&row.password_hash)
            .bind(row.admin)
            .bind(row.disabled)
            .bind(row.created_at)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn user_by_id(&self, id: &str) -> Result<Option<UserRow>, sqlx::Error> {
        const SQL: &str = concat!("SELECT ", user_columns!(), " FROM users WHERE id = $1");
        on_pool!(self, pool => sqlx::query_as::<_, UserRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    pub async fn user_by_name(&self, name: &str) -> Result<Option<UserRow>, sqlx::Error> {
        const SQL: &str = concat!("SELECT ", user_columns!(), " FROM users WHERE name = $1");
        on_pool!(self, pool => sqlx::query_as::<_, UserRow>(SQL).bind(name).fetch_optional(pool).await)
    }

    /// Oldest first.
    pub async fn list_users(
        &self,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<UserRow>, i64), sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            user_columns!(),
            " FROM users ORDER BY created_at, id LIMIT $1 OFFSET $2"
        );
        const COUNT: &str = "SELECT COUNT(*) FROM users";
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, UserRow>(SQL).bind(limit).bind(offset).fetch_all(pool).await?;
            let (total,): (i64,) = sqlx::query_as(COUNT).fetch_one(pool).await?;
            Ok((rows, total))
        })
    }

    /// How many users there are (0 on a new service).
    pub async fn count_users(&self) -> Result<i64, sqlx::Error> {
        const SQL: &str = "SELECT COUNT(*) FROM users";
        on_pool!(self, pool => sqlx::query_as::<_, (i64,)>(SQL).fetch_one(pool).await.map(|r| r.0))
    }

    /// How many admins there are.
    pub async fn count_admins(&self) -> Result<i64, sqlx::Error> {
        const SQL: &str = "SELECT COUNT(*) FROM users WHERE admin = 1";
        on_pool!(self, pool => sqlx::query_as::<_, (i64,)>(SQL).fetch_one(pool).await.map(|r| r.0))
    }

    /// Disable a user and end its sessions; true when the user exists.
    pub async fn disable_user(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE users SET disabled = 1 WHERE id = $1";
        const END: &str = "DELETE FROM sessions WHERE user_id = $1";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let found = sqlx::query(SQL).bind(id).execute(&mut *tx).await?.rows_affected() > 0;
            sqlx::query(END).bind(id).execute(&mut *tx).await?;
            tx.commit().await?;
            Ok(found)
        })
    }

    pub async fn insert_token(&self, row: &TokenRow) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO api_tokens (id, user_id, name, secret_hash, created_at, last_used_at, expires_at) VALUES ($1, $2, $3, $4, $5, $6, $7)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.user_id)
            .bind(&row.name)
            .bind(&row.secret_hash)
            .bind(row.created_at)
            .bind(row.last_used_at)
            .bind(row.expires_at)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn token_by_id(&self, id: &str) -> Result<Option<TokenRow>, sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            token_columns!(),
            " FROM api_tokens WHERE id = $1"
        );
        on_pool!(self, pool => sqlx::query_as::<_, TokenRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// A user's tokens, oldest first.
    pub async fn list_tokens(
        &self,
        user_id: &str,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<TokenRow>, i64), sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            token_columns!(),
            " FROM api_tokens WHERE user_id = $1 ORDER BY created_at, id LIMIT $2 OFFSET $3"
        );
        const COUNT: &str = "SELECT COUNT(*) FROM api_tokens WHERE user_id = $1";
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, TokenRow>(SQL).bind(user_id).bind(limit).bind(offset).fetch_all(pool).await?;
            let (total,): (i64,) = sqlx::query_as(COUNT).bind(user_id).fetch_one(pool).await?;
            Ok((rows, total))
        })
    }

    /// Revoke one of a user's tokens; true when it was theirs and existed.
    pub async fn delete_token(&self, user_id: &str, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM api_tokens WHERE id = $1 AND user_id = $2";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).bind(user_id).execute(pool).await.map(|r| r.rows_affected() > 0))
    }

    pub async fn touch_token(&self, id: &str, now: i64) -> Result<(), sqlx::Error> {
        const SQL: &str = "UPDATE api_tokens SET last_used_at = $2 WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).bind(now).execute(pool).await.map(|_| ()))
    }

    pub async fn insert_session(&self, row: &SessionRow) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO sessions (id, user_id, secret_hash, csrf_token, created_at, last_used_at, expires_at) VALUES ($1, $2, $3, $4, $5, $6, $7)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.user_id)
            .bind(&row.secret_hash)
            .bind(&row.csrf_token)
            .bind(row.created_at)
            .bind(row.last_used_at)
            .bind(row.expires_at)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn session_by_id(&self, id: &str) -> Result<Option<SessionRow>, sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            session_columns!(),
            " FROM sessions WHERE id = $1"
        );
        on_pool!(self, pool => sqlx::query_as::<_, SessionRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    pub async fn touch_session(&self, id: &str, now: i64) -> Result<(), sqlx::Error> {
        const SQL: &str = "UPDATE sessions SET last_used_at = $2 WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).bind(now).execute(pool).await.map(|_| ()))
    }

    /// Forget the sessions that have ended (expired, or idle since
    /// `idle_since`); how many.
    pub async fn purge_sessions(&self, now: i64, idle_since: i64) -> Result<u64, sqlx::Error> {
        const SQL: &str = "DELETE FROM sessions WHERE expires_at <= $1 OR last_used_at <= $2";
        on_pool!(self, pool => sqlx::query(SQL).bind(now).bind(idle_since).execute(pool).await.map(|r| r.rows_affected()))
    }

    /// Set a user's password hash and end its sessions (a changed password
    /// signs out every browser that used the old one).
    pub async fn set_password_hash(&self, id: &str, hash: &str) -> Result<(), sqlx::Error> {
        const SQL: &str = "UPDATE users SET password_hash = $2 WHERE id = $1";
        const END: &str = "DELETE FROM sessions WHERE user_id = $1";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            sqlx::query(SQL).bind(id).bind(hash).execute(&mut *tx).await?;
            sqlx::query(END).bind(id).execute(&mut *tx).await?;
            tx.commit().await
        })
    }

    pub async fn delete_session(&self, id: &str) -> Result<(), sqlx::Error> {
        const SQL: &str = "DELETE FROM sessions WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).execute(pool).await.map(|_| ()))
    }
}
